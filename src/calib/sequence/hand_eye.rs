//! Hand-eye calibration from synchronized motions (`A_k X = X B_k`).
