#pragma once
// Point-to-plane ICP's step (Chen and Medioni 1991; not in the paper), for a moving sensor's
// matches where asked (MotionSettings::plane_objective, --moving-point-to-plane): where the
// paper's point-to-point step also pulls each data point sideways along the surface it shares
// with its model point (towards that one sampled point), the plane's distance alone is what a
// pair measures here, so the sampling of a thinned local map no longer moves the scan along its
// surfaces. The sums (search/plane_sums.hpp) come from the backend; the 6x6 solve runs here, on
// the host.
//
// Units: centimetres and radians. Thread-safety: a pure function.
#include <optional>

#include "minemap/core/pose.hpp"
#include "minemap/search/plane_sums.hpp"

namespace minemap {

/// The data's step (data frame) that minimises the linearised objective of `sums`: the model's
/// motion U = (exp(w), t) about the reference, inverted. A direction no pair measures (a slide
/// along a smooth tunnel) gets no motion rather than an arbitrary one: J^T J's diagonal is raised
/// by a millionth of itself. nullopt when fewer than 6 pairs, or the sums are not finite or singular.
std::optional<Pose> plane_step(const PlaneSums& sums);

}  // namespace minemap
