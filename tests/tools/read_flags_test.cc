// The snapshot-reading flags that ingest and render --reference share.
#include "tools/read_flags.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

// --box-size and --ignore-box as ingest and render --reference read them.
TEST(ReadFlags, BoxFlagsBecomeReadOptionsOrAnError) {
  ReadFlags flags;
  EXPECT_LT(ReadOptionsFrom(flags).box_size_override, 0);
  EXPECT_FALSE(ReadOptionsFrom(flags).ignore_box);
  flags.box_size = 250;
  EXPECT_EQ(ReadOptionsFrom(flags).box_size_override, 250);
  flags.ignore_box = true;
  EXPECT_THROW(ReadOptionsFrom(flags), Error) << "both";
  flags.box_size = -1;
  EXPECT_TRUE(ReadOptionsFrom(flags).ignore_box);
  flags.ignore_box = false;
  for (const double bad : {std::nan(""), HUGE_VAL, -5.0}) {
    flags.box_size = bad;
    try {
      ReadOptionsFrom(flags);
      ADD_FAILURE() << bad;
    } catch (const Error& error) {
      EXPECT_EQ(error.kind(), ErrorKind::kInvalidArgument);
      EXPECT_NE(std::string(error.what()).find("--box-size"), std::string::npos) << error.what();
    }
  }
}

}  // namespace
}  // namespace octocosm
