#pragma once
#include "accel/builder.h"

namespace canopy {

// Karras and Aila 2013's whole pipeline ("STreelet" in the quality-metrics paper): budgeted pre-splitting with
// a 30% quota (accel/presplit.h), LBVH over the pieces, then three rounds of treelet restructuring.
Bvh build_streelet(BuildInput&& input, const BuildSettings& settings);

}  // namespace canopy
