//! Calibration from a recording: two sensors' synchronized frames of a drive, including sensors
//! that never see the same thing at the same time.
//!
//! * [`hand_eye`]: the extrinsic from pairs of synchronized motions (`A_k X = X B_k`).

pub mod hand_eye;
