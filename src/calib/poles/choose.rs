//! Step 6 of the [module docs](super): the winning hypothesis, its margin and the poles' fit.

/// Two refined hypotheses within this rotation (radians) ...
pub const SAME_POSE_ANGLE: f64 = 0.01;
/// ... and this translation (metres) of each other are the same solution.
pub const SAME_POSE_DISTANCE: f64 = 0.05;
/// A score margin below this flags the choice as ambiguous.
pub const AMBIGUITY_MARGIN: f64 = 1.0;
/// A score margin below this refuses the calibration: the best two are indistinguishable.
pub const REFUSE_MARGIN: f64 = 0.2;
/// Largest RMS distance (metres) of a matched pole's points from its axis model at the result;
/// correct results stay under 1 cm, a pose from mismatched poles lands decimetres off.
pub const MAX_POLE_RMSE: f64 = 0.05;
/// What [`MAX_POLE_RMSE`] allows in addition for [`AxisFit::Line`](super::AxisFit::Line), whose residuals include the
/// pole's thickness (metres).
pub const LINE_FIT_THICKNESS: f64 = 0.2;
