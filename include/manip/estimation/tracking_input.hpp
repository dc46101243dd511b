#pragma once
// Position "tracked" (PositionSource::tracked, docs/estimator.md, "Which
// position"): the encoder is the person's position, and the admittance
// integrated the reference x_ref = x + e. With M_adm ẍ_ref + D_adm ẋ_ref =
// f_s + u_pert and the person at x, the loop on the encoder is
//   (M_BSP + M_adm + M_handle) ẍ + (D + D_adm) ẋ + K x = u_pert − M_adm ë − D_adm ė,
// so the tracking error is a known force with none of the person's
// parameters in it, and eq. 21 is exact with the reference's kinematics for
// the admittance and the encoder's for the handle:
//   Δu_ext = u_pert − M_adm Δẍ_ref − D_adm Δẋ_ref − M_handle Δẍ.
// The loop models (pem, oe) see the whole motion from before onset, so they
// get ė, ë of the whole e by the pipeline's Savitzky-Golay derivatives; the
// paper's methods get eq. 21 from both positions isolated alike.
#include <span>
#include <vector>

#include "manip/common/frames.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

// `vw` and `windows` were made from `encoder` (its x_m the encoder);
// x_ref_aligned is aligned_reference(encoder, shift). Adds the tracking
// input to each window's u_n (windows with no samples are skipped) and
// corrects vw.du_ext_adm. Throws std::invalid_argument as
// isolate_variational does.
void add_tracking_input(const SessionInfo& info, const TrialData& encoder, const std::vector<Vec2>& x_ref_aligned,
                        const PipelineSettings& pipe, VariationalWindow& vw, std::span<OeWindow* const> windows);

}  // namespace manip::estimation
