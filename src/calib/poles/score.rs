//! Step 6 of the [module docs](super): the score of a refined hypothesis.

/// Unit of the axis RMS term of a hypothesis score (metres).
pub const AXIS_RMS_SCALE: f64 = 0.02;
/// Unit of the ground-normal angle term (radians, 5 degrees).
pub const GROUND_ANGLE_SCALE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Unit of the ground-offset term (metres).
pub const GROUND_OFFSET_SCALE: f64 = 0.2;
/// Unit of the `1 - overlap` term.
pub const OVERLAP_SCALE: f64 = 0.1;
/// Target points (at most, by a fixed stride) used for the overlap term.
pub const OVERLAP_SAMPLE: usize = 1500;
