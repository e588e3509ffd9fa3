// Physical time to a fractional epoch (index/dataset.h FractionalEpochAt):
// the neighbouring epochs by their recorded scale factors, t linear in the
// scale factor between them; and the errors, which name the store.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "base/error.h"
#include "index/dataset.h"
#include "storage/store_writer.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

using Scale = PhysicalTime::Scale;

PhysicalTime Redshift(double z) { return {Scale::kRedshift, z}; }
PhysicalTime ScaleFactor(double a) { return {Scale::kScaleFactor, a}; }

// The message of the Error::InvalidArgument that `f` throws ("" and a
// failure when it throws none, or another kind).
std::string InvalidArgumentMessage(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument) << e.what();
    return e.what();
  }
  ADD_FAILURE() << "no error";
  return "";
}

// Four epochs, unevenly spaced in a: z = 9, 4, 1, 0.
const std::vector<std::optional<double>> kUneven = {0.1, 0.2, 0.5, 1.0};

TEST(EpochTime, UnevenlySpacedEpochsInterpolateLinearlyInTheScaleFactor) {
  EXPECT_DOUBLE_EQ(FractionalEpochAt(kUneven, ScaleFactor(0.15), "s"), 0.5);
  EXPECT_DOUBLE_EQ(FractionalEpochAt(kUneven, ScaleFactor(0.35), "s"), 1.5);
  EXPECT_DOUBLE_EQ(FractionalEpochAt(kUneven, ScaleFactor(0.8), "s"), 2.6);
  // z = 0.5 is a = 2/3: a third of the way from a = 0.5 to a = 1 (not
  // halfway, as it would be linear in z).
  EXPECT_NEAR(FractionalEpochAt(kUneven, Redshift(0.5), "s"), 2 + 1.0 / 3, 1e-12);
  // z = 2 is a = 1/3: between epochs 1 and 2.
  EXPECT_NEAR(FractionalEpochAt(kUneven, Redshift(2), "s"), 1 + (1.0 / 3 - 0.2) / 0.3, 1e-12);
  // Later times, later epochs.
  double previous = -1;
  for (double a = 0.1; a <= 1; a += 0.01) {
    const double e = FractionalEpochAt(kUneven, ScaleFactor(a), "s");
    EXPECT_GT(e, previous) << "a = " << a;
    previous = e;
  }
}

TEST(EpochTime, AnEpochsOwnTimeIsThatEpochExactly) {
  for (std::size_t e = 0; e < kUneven.size(); ++e) {
    const double a = *kUneven[e];
    EXPECT_EQ(FractionalEpochAt(kUneven, ScaleFactor(a), "s"), static_cast<double>(e));
    // The redshift as a header records it, 1 / a - 1, rounds back to a only
    // to about an ulp; it is still the epoch, exactly.
    EXPECT_EQ(FractionalEpochAt(kUneven, Redshift(1 / a - 1), "s"), static_cast<double>(e));
    EXPECT_EQ(FractionalEpochAt(kUneven, ScaleFactor(a * (1 + 3e-8)), "s"), static_cast<double>(e));
  }
  // A time recorded in single precision is its epoch too.
  const std::vector<std::optional<double>> single = {static_cast<double>(1.0f / 3), 0.5};
  EXPECT_EQ(FractionalEpochAt(single, Redshift(2), "s"), 0.0);
  // One epoch: its own time, and nothing else.
  EXPECT_EQ(FractionalEpochAt({0.25}, Redshift(3), "s"), 0.0);
  EXPECT_NE(InvalidArgumentMessage([] { FractionalEpochAt({0.25}, Redshift(2), "s"); }), "");
}

TEST(EpochTime, TimesOutsideTheEpochsAreRefusedNamingTheStore) {
  for (const PhysicalTime time : {ScaleFactor(0.05), ScaleFactor(1.5), Redshift(10), Redshift(-0.5)}) {
    SCOPED_TRACE(time.ToString());
    const std::string message = InvalidArgumentMessage([&] { FractionalEpochAt(kUneven, time, "/data/run7"); });
    EXPECT_NE(message.find("/data/run7"), std::string::npos) << message;
    EXPECT_NE(message.find("outside"), std::string::npos) << message;
    EXPECT_NE(message.find(time.ToString()), std::string::npos) << message;
  }
  // The range is given in the caller's scale.
  EXPECT_NE(InvalidArgumentMessage([] { FractionalEpochAt(kUneven, Redshift(10), "s"); }).find("from 9 (epoch 0) to 0 (epoch 3)"),
            std::string::npos);
  EXPECT_NE(InvalidArgumentMessage([] { FractionalEpochAt(kUneven, ScaleFactor(2), "s"); }).find("from 0.1 (epoch 0) to 1 (epoch 3)"),
            std::string::npos);
  // Values that are no time at all.
  for (const PhysicalTime time : {Redshift(-1), Redshift(-2), Redshift(NAN), ScaleFactor(0), ScaleFactor(-0.5),
                                  ScaleFactor(INFINITY)}) {
    SCOPED_TRACE(time.ToString());
    EXPECT_NE(InvalidArgumentMessage([&] { FractionalEpochAt(kUneven, time, "s"); }), "");
  }
}

TEST(EpochTime, EpochsWithoutAScaleFactorAreRefused) {
  const std::vector<std::optional<double>> none = {std::nullopt, std::nullopt};
  const std::string message = InvalidArgumentMessage([&] { FractionalEpochAt(none, Redshift(1), "/data/plain"); });
  EXPECT_NE(message.find("/data/plain"), std::string::npos) << message;
  EXPECT_NE(message.find("no scale factor"), std::string::npos) << message;
  // One epoch without is enough: the interval around it has no time scale.
  const std::vector<std::optional<double>> one = {0.5, std::nullopt, 1.0};
  EXPECT_NE(InvalidArgumentMessage([&] { FractionalEpochAt(one, ScaleFactor(0.6), "s"); }).find("epoch 1"),
            std::string::npos);
}

TEST(EpochTime, EpochsWhoseTimesDoNotIncreaseAreRefused) {
  for (const std::vector<std::optional<double>>& recorded :
       {std::vector<std::optional<double>>{0.1, 0.3, 0.3}, std::vector<std::optional<double>>{0.5, 0.2, 0.7}}) {
    const std::string message = InvalidArgumentMessage([&] { FractionalEpochAt(recorded, ScaleFactor(0.25), "/data/odd"); });
    EXPECT_NE(message.find("/data/odd"), std::string::npos) << message;
    EXPECT_NE(message.find("increase"), std::string::npos) << message;
  }
}

// A store of three empty epochs whose dataset metadata records each input
// header as ingest does: time a, redshift 1 / a - 1, cosmological or not.
std::string WriteStore(const std::filesystem::path& directory, const std::vector<double>& scale_factors,
                       bool cosmological) {
  nlohmann::json dataset = {{"capacity", 100}, {"max_level", 10}, {"epochs", nlohmann::json::array()}};
  StoreWriter writer(directory.string(), nlohmann::json::object(), nlohmann::json::object());
  for (const double a : scale_factors) {
    writer.BeginEpoch(a, 1 / a - 1);
    writer.EndEpoch();
    dataset["epochs"].push_back(
        {{"cube", {{"origin", {0, 0, 0}}, {"size", 1}, {"periodic", true}}},
         {"points", 0},
         {"input", {{"time", a}, {"redshift", 1 / a - 1}, {"cosmological", cosmological}}}});
  }
  writer.SetDataset(dataset);
  writer.Finish();
  return directory.string();
}

TEST(EpochTime, DatasetReadsTheRecordedScaleFactors) {
  testing_support::TempDir dir("epoch-time");
  const Dataset d = Dataset::Open(WriteStore(dir.path() / "cosmological", {0.25, 0.4, 1.0}, true));
  ASSERT_EQ(d.epoch_count(), 3u);
  EXPECT_EQ(d.scale_factor(1), 0.4);
  EXPECT_EQ(d.FractionalEpochAt(Redshift(1.5)), 1.0);
  EXPECT_DOUBLE_EQ(d.FractionalEpochAt(ScaleFactor(0.7)), 1.5);
  EXPECT_DOUBLE_EQ(d.FractionalEpochAt(Redshift(3)), 0.0);
  EXPECT_NE(InvalidArgumentMessage([&] { d.FractionalEpochAt(Redshift(4)); }).find(d.store().directory()),
            std::string::npos);

  const Dataset plain = Dataset::Open(WriteStore(dir.path() / "plain", {0.25, 0.4, 1.0}, false));
  EXPECT_FALSE(plain.scale_factor(0).has_value());
  const std::string message = InvalidArgumentMessage([&] { plain.FractionalEpochAt(ScaleFactor(0.4)); });
  EXPECT_NE(message.find(plain.store().directory()), std::string::npos) << message;
  EXPECT_NE(message.find("not from a cosmological run"), std::string::npos) << message;
}

}  // namespace
}  // namespace octocosm
