//! Step 4, continued: which runner-ups make the result ambiguous (the check rules some out; a
//! repeated structure can hide a rival the ranking never sees).

/// A slid copy of the best pose (a repeated structure one period off) that passes the check makes
/// the result ambiguous when the best pose puts more than this share of the points into the other
/// sensor's free space (the larger of the two ways; the truth of a simulated scene puts under
/// 1 %) ...
pub(super) const SLID_FREE_SPACE_MIN: f64 = 0.01;
/// ... and the slid copy at most this fraction of the best pose's share.
pub(super) const SLID_FREE_SPACE_RATIO: f64 = 0.5;

/// Whether a pose that puts the share `free` of the points into the other sensor's free space
/// (the larger of the two ways, on the check's figures) keeps it clearly clearer than one that
/// puts `other`: `other` above [`SLID_FREE_SPACE_MIN`] and `free` at most
/// [`SLID_FREE_SPACE_RATIO`] of it.
pub(super) fn clearer(free: f64, other: f64) -> bool {
    other > SLID_FREE_SPACE_MIN && free <= SLID_FREE_SPACE_RATIO * other
}

/// A rival the check rules out is dismissed only when it is turned at least this far from the best
/// pose (radians, 10 degrees); see `calibrate_targetless`.
pub(super) const RULED_OUT_TURN: f64 = 10.0 * std::f64::consts::PI / 180.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clearer_needs_the_other_pose_in_free_space_and_half_as_much() {
        assert!(clearer(0.006, 0.016));
        assert!(!clearer(0.009, 0.016));
        assert!(!clearer(0.0, 0.008));
    }
}
