//! Options of the targetless method ([`super::calibrate_targetless`]) and their defaults.

use crate::check::CheckOptions;
use crate::error::{ensure_positive, Error, Result};
use crate::icp::IcpOptions;

/// Iterations of the final ICP (default of `TargetlessOptions::icp_options.max_iterations`). On
/// a sparse 16-beam scan the pose keeps creeping 0.5-1 mm per iteration along the weakest
/// direction for tens of iterations; at 30, eight solvable adversarial scenes (of 1000) were
/// refused as unsettled that settle on the truth within 100.
const FINAL_ICP_ITERATIONS: usize = 100;
/// Default of [`TargetlessOptions::challenger_range`].
const CHALLENGER_RANGE: f64 = 2.0;
/// Default of [`TargetlessOptions::min_agreement`].
const MIN_AGREEMENT: f64 = 0.10;

/// Options of [`calibrate_targetless`](super::calibrate_targetless).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetlessOptions {
    /// Plane inlier distance (metres), or `None` to estimate it per cloud (3 sigma, within
    /// 3 to 10 cm).
    pub distance_threshold: Option<f64>,
    /// Voxel side of the downsampling (metres).
    pub voxel_size: f64,
    /// Most planes extracted per cloud.
    pub max_planes: usize,
    /// Fewest inliers (voxels) of a plane.
    pub min_inliers: usize,
    /// Angles between normals that agree (radians).
    pub normal_tolerance: f64,
    /// Offsets of planes that agree (metres).
    pub offset_tolerance: f64,
    /// Hypotheses polished by a short ICP and scored by point agreement.
    pub max_verified: usize,
    /// Largest distance between the sensors (metres): the sensors of one rig are a few metres
    /// apart at most. Poses beyond it are never returned. `f64::INFINITY` keeps all.
    pub max_translation: f64,
    /// Hypotheses up to this multiple of `max_translation` away are verified too, as
    /// **challengers** (see the module docs, step 4): never returned, but when one verifies
    /// best the calibration is refused as out of range, and when one comes within
    /// 90 % of the best, as ambiguous. In 1000 adversarial scenes
    /// every wrong answer for sensors 5.3-8 m apart (a shift along the street, a quarter or half
    /// turn) was the best pose within 5 m. The price: on streets that repeat themselves along
    /// their axis a pose beyond the bound can fit as well as the truth within it, and the
    /// calibration is refused. `1.0` trusts the bound (no challengers); at least 1.
    pub challenger_range: f64,
    /// Run the final ICP on the whole clouds.
    pub icp: bool,
    /// Options of the final ICP.
    pub icp_options: IcpOptions,
    /// Smallest share of the translation (and rotation) information in its weakest direction;
    /// below it the calibration is refused as unobservable. A pose grown from the ground sweep
    /// must hold one and a half times this in its weakest translation direction.
    pub min_information_share: f64,
    /// Smallest share of the sampled target points the best verified pose brings within 25 cm of
    /// the reference; below it the calibration is refused as no agreement. A pose grown from the
    /// ground sweep (one plane pair and ICP, no second pair to corroborate it) must reach one and
    /// a half times this. So little common structure cannot tell the true pose from a wrong one:
    /// in 2000 adversarial scenes (seeds 0-999 and 7000-7999) every correct result explained at
    /// least 14.3 % of the target (18.4 % from the sweep), while a room of two identical boxes
    /// came back turned 176 degrees explaining 4.2 % (the target's ground laid on a box face) and
    /// a row of three boxes turned 90 degrees from the sweep explaining 11.8 %.
    pub min_agreement: f64,
    /// Also hypothesise from the largest plane of each cloud (the ground of a road scene) turned
    /// about its normal in steps of 15 degrees, each polished by ICP: this finds the pose
    /// when the clouds share no pair of non-parallel planes.
    pub ground_sweep: bool,
    /// Refuse (rather than flag [`TargetlessDetails::ambiguous`](super::TargetlessDetails::ambiguous)) when a distinct pose
    /// verifies almost as well as the best (at least 75 % of its score).
    pub refuse_ambiguous: bool,
    /// Seed of the RANSAC sampler.
    pub seed: u64,
    /// The final check every result must pass ([`crate::check`]).
    pub check: CheckOptions,
}

impl Default for TargetlessOptions {
    fn default() -> Self {
        TargetlessOptions {
            distance_threshold: None,
            voxel_size: 0.1,
            max_planes: 10,
            min_inliers: 30,
            normal_tolerance: 5f64.to_radians(),
            offset_tolerance: 0.3,
            max_verified: 24,
            max_translation: 5.0,
            challenger_range: CHALLENGER_RANGE,
            icp: true,
            icp_options: IcpOptions {
                max_iterations: FINAL_ICP_ITERATIONS,
                ..IcpOptions::default()
            },
            min_information_share: 0.01,
            min_agreement: MIN_AGREEMENT,
            ground_sweep: true,
            refuse_ambiguous: true,
            seed: 0,
            check: CheckOptions::default(),
        }
    }
}

impl TargetlessOptions {
    pub(super) fn validate(&self) -> Result<()> {
        if let Some(t) = self.distance_threshold {
            ensure_positive("distance_threshold", t)?;
        }
        ensure_positive("voxel_size", self.voxel_size)?;
        ensure_positive("normal_tolerance", self.normal_tolerance)?;
        ensure_positive("offset_tolerance", self.offset_tolerance)?;
        if self.max_translation.is_nan() || self.max_translation <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "max_translation must be positive (or inf), got {}",
                self.max_translation
            )));
        }
        if !(0.0..1.0 / 3.0).contains(&self.min_information_share) {
            return Err(Error::InvalidInput(format!(
                "min_information_share must be in [0, 1/3), got {}",
                self.min_information_share
            )));
        }
        if !(0.0..1.0).contains(&self.min_agreement) {
            return Err(Error::InvalidInput(format!(
                "min_agreement must be in [0, 1), got {}",
                self.min_agreement
            )));
        }
        if self.challenger_range.is_nan() || self.challenger_range < 1.0 {
            return Err(Error::InvalidInput(format!(
                "challenger_range must be at least 1 (or inf), got {}",
                self.challenger_range
            )));
        }
        if self.max_planes < 2 || self.max_verified == 0 || self.min_inliers < 3 {
            return Err(Error::InvalidInput(format!(
                "need max_planes >= 2, max_verified >= 1 and min_inliers >= 3; got {}, {}, {}",
                self.max_planes, self.max_verified, self.min_inliers
            )));
        }
        Ok(())
    }
}
