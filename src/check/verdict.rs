//! The last stage of a check: the verdict and its reason from what the other stages found, in
//! order (overlap, free space, agreement, the re-alignment, observability).

use nalgebra::Vector3;

use super::agreement::{Agreement, FreeSpace};
use super::realign::{Correction, Counted, Detectable};
use super::{CheckOptions, Verdict, MIN_OVERLAP_POINTS};
use crate::error::FailureKind;

/// What the stages of a check found at one pose.
pub(super) struct Findings<'a> {
    pub(super) agreement: &'a Agreement,
    pub(super) free_space: &'a FreeSpace,
    /// Whether the local re-alignment found enough correspondences.
    pub(super) realigned: bool,
    pub(super) correction: &'a Correction,
    pub(super) agreement_gain: f64,
    pub(super) detectable: &'a Detectable,
    pub(super) counted: &'a Counted,
    pub(super) options: &'a CheckOptions,
}

/// A verdict, the failure kind a calibration refusing the pose reports, and the reason.
pub(super) type Judgement = (Verdict, Option<FailureKind>, String);

fn pct(v: f64) -> f64 {
    v * 100.0
}

/// The verdict: the first finding against the pose, or consistent.
pub(super) fn verdict(f: &Findings<'_>) -> Judgement {
    overlap_and_agreement(f)
        .or_else(|| realignment(f))
        .or_else(|| observability(f))
        .unwrap_or_else(|| consistent(f))
}

/// Too little overlap (unverifiable), too many free-space violations or too little agreement
/// (inconsistent).
fn overlap_and_agreement(f: &Findings<'_>) -> Option<Judgement> {
    let (a, options) = (f.agreement, f.options);
    let (overlap_t, overlap, agreement, reverse_agreement, limit) = (
        a.overlap_points,
        a.overlap,
        a.agreement,
        a.reverse_agreement,
        a.limit,
    );
    let (normals_t, normals_r) = a.normals;
    let (violations, reverse_violations) =
        (f.free_space.violations, f.free_space.reverse_violations);
    if overlap_t < MIN_OVERLAP_POINTS
        || normals_t.min(normals_r) < MIN_OVERLAP_POINTS / 2
        || overlap < options.min_overlap
    {
        Some((
            Verdict::Unverifiable,
            Some(FailureKind::TooFewFeatures),
            format!(
                "too little overlap: {overlap_t} target points ({:.1} %) land within {:.2} m of \
                 the reference (need {MIN_OVERLAP_POINTS} and {:.1} %)",
                pct(overlap),
                options.overlap_distance,
                pct(options.min_overlap)
            ),
        ))
    } else if violations.max(reverse_violations) > options.max_violations {
        Some((
            Verdict::Inconsistent,
            Some(FailureKind::NoAgreement),
            format!(
                "{:.1} % of the target points and {:.1} % of the reference points land in space \
                 the other sensor saw through (> {:.1} %)",
                pct(violations),
                pct(reverse_violations),
                pct(options.max_violations)
            ),
        ))
    } else if agreement.min(reverse_agreement) < options.min_agreement {
        Some((
            Verdict::Inconsistent,
            Some(FailureKind::NoAgreement),
            format!(
                "only {:.1} % of the overlapping target points and {:.1} % of the reference points \
                 lie within {:.1} cm of the other's surface (< {:.0} %)",
                pct(agreement),
                pct(reverse_agreement),
                limit * 100.0,
                pct(options.min_agreement)
            ),
        ))
    } else {
        None
    }
}

/// No re-alignment (unverifiable), or one that counts against the pose: a correction beyond its
/// tolerance or a clear agreement gain (inconsistent).
fn realignment(f: &Findings<'_>) -> Option<Judgement> {
    let (c, d, options) = (f.correction, f.detectable, f.options);
    let (correction_rotation, correction_translation) = (c.rotation, c.translation);
    let (detectable_rotation, detectable_translation) = (d.rotation, d.translation);
    let agreement_gain = f.agreement_gain;
    if !f.realigned {
        Some((
            Verdict::Unverifiable,
            Some(FailureKind::TooFewFeatures),
            "the local re-alignment found too few correspondences".to_string(),
        ))
    } else if f.counted.excess > 1.0 {
        Some((
            Verdict::Inconsistent,
            Some(FailureKind::NoAgreement),
            format!(
                "the scene prefers a pose {:.2} deg / {:.1} cm away (tolerance {:.2} deg / {:.1} cm \
                 where the overlap constrains the pose well, {:.1} deg / {:.0} cm where it does not)",
                correction_rotation.to_degrees(),
                correction_translation * 100.0,
                detectable_rotation.to_degrees(),
                detectable_translation * 100.0,
                options.weak_rotation_tolerance.to_degrees(),
                options.weak_translation_tolerance * 100.0
            ),
        ))
    } else if f.counted.gain > options.max_agreement_gain {
        Some((
            Verdict::Inconsistent,
            Some(FailureKind::NoAgreement),
            format!(
                "a pose {:.2} deg / {:.1} cm away fits clearly more points: the agreement rises by \
                 {:.1} points both ways (> {:.1})",
                correction_rotation.to_degrees(),
                correction_translation * 100.0,
                pct(agreement_gain),
                pct(options.max_agreement_gain)
            ),
        ))
    } else {
        None
    }
}

/// A translation direction or rotation axis the overlap does not constrain (unverifiable).
fn observability(f: &Findings<'_>) -> Option<Judgement> {
    let fmt = |v: &Vector3<f64>| format!("[{:.2}, {:.2}, {:.2}]", v.x, v.y, v.z);
    let (weakest_translation, weakest_rotation, options) = (
        f.correction.weakest_translation,
        f.correction.weakest_rotation,
        f.options,
    );
    if weakest_translation.1 < options.min_information_share {
        Some((
            Verdict::Unverifiable,
            Some(FailureKind::Unobservable),
            format!(
                "the overlap does not constrain the translation along {} ({:.2} % of the \
                 information < {:.2} %): an error along it would go unseen",
                fmt(&weakest_translation.0),
                pct(weakest_translation.1),
                pct(options.min_information_share)
            ),
        ))
    } else if weakest_rotation.1 < options.min_information_share {
        Some((
            Verdict::Unverifiable,
            Some(FailureKind::Unobservable),
            format!(
                "the overlap does not constrain the rotation about {} ({:.2} % of the information \
                 < {:.2} %): an error about it would go unseen",
                fmt(&weakest_rotation.0),
                pct(weakest_rotation.1),
                pct(options.min_information_share)
            ),
        ))
    } else {
        None
    }
}

/// Consistent, saying how far the re-alignment moved (and when it was no evidence, why).
fn consistent(f: &Findings<'_>) -> Judgement {
    let (correction_rotation, correction_translation) =
        (f.correction.rotation, f.correction.translation);
    (
        Verdict::Consistent,
        None,
        match f.counted.realign_violations {
            None => format!(
                "the clouds agree and a local re-alignment moves the pose by {:.2} deg / \
                 {:.1} cm",
                correction_rotation.to_degrees(),
                correction_translation * 100.0
            ),
            Some(moved) => format!(
                "the clouds agree; a local re-alignment {:.2} deg / {:.1} cm away fits the \
                 surfaces better but puts {:.1} % of the points into the other sensor's \
                 free space (here {:.1} %)",
                correction_rotation.to_degrees(),
                correction_translation * 100.0,
                pct(moved),
                pct(f.free_space.worse())
            ),
        },
    )
}
