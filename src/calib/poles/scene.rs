//! Step 7 of the [module docs](super): settling the pole pose on the whole scene.

/// The scene's re-alignment of the pole pose is kept only within this rotation (radians, 3
/// degrees) ...
pub const SCENE_REFINE_ANGLE: f64 = 3.0 * std::f64::consts::PI / 180.0;
/// ... and this translation (metres) of it, where the poles still fit ([`MAX_POLE_RMSE`](super::MAX_POLE_RMSE)).
pub const SCENE_REFINE_DISTANCE: f64 = 0.2;
