// A storage header that includes the renderer: the layering check must
// refuse it (tests/CMakeLists.txt, layering_check_catches_violations).
#pragma once

#include "render/tone_map.h"
