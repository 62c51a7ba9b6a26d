//! Calibration from a recording: two sensors' synchronized frames of a drive, including sensors
//! that never see the same thing at the same time.
//!
//! * [`hand_eye`](fn@hand_eye): the extrinsic from pairs of synchronized motions (`A_k X = X B_k`): the
//!   rotation and the translation up to what the motion leaves unobserved (the height, when the
//!   drive is planar).

pub mod hand_eye;

pub use hand_eye::{hand_eye, HandEye, HandEyeOptions, MotionPair};
