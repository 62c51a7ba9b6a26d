//! One result shape for every method: [`Calibration`] holds what every method reports under the
//! same names (the pose, the check, per-feature residuals and inliers, the covariance, the
//! refinement that produced the pose, the timings) and the method's own diagnostics in
//! [`details`](Calibration::details).
//!
//! Each method's entry point returns its own details ([`PlanarCalibration`] is
//! `Calibration<PlanarDetails>`, and so on); [`calibrate`](super::calibrate) and the rig return
//! `Calibration` (`Calibration<Details>`), whose [`Details`] says which method it was.
//! [`Calibration::into_any`] converts the first into the second. The Python result
//! (`lidarcal.CalibrationResult`) carries the same fields under the same names, its `details`
//! one of `PlanarDetails`, `PoleDetails` or `TargetlessDetails`.

use nalgebra::{Isometry3, Matrix6};

use super::method::Method;
use super::planes::PlanarDetails;
use super::poles::PoleDetails;
use super::targetless::TargetlessDetails;
use super::Timings;
use crate::check::CheckReport;
use crate::icp::IcpResult;
use crate::lm::LmReport;

/// What a calibration returned (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration<D = Details> {
    /// The calibrated `reference_from_target`.
    pub reference_from_target: Isometry3<f64>,
    /// The method's estimate before any refinement (the corner's closed form, the chosen pole
    /// hypothesis' closed form, the winning targetless hypothesis).
    pub initial_reference_from_target: Isometry3<f64>,
    /// The final check's report (its verdict is always consistent: other poses are refused).
    pub check: CheckReport,
    /// RMS residual (metres) of each matched feature at the result, both clouds together:
    /// point-to-plane per matched plane, point-to-axis per matched pole.
    pub rmse: Vec<f64>,
    /// Indices into the reference cloud of each matched feature's points (plane or pole).
    pub inliers_reference: Vec<Vec<usize>>,
    /// Indices into the target cloud of each matched feature's points.
    pub inliers_target: Vec<Vec<usize>>,
    /// Covariance of the left-perturbation tangent `[rho; phi]` of the result (metres,
    /// radians), when the solver gives one.
    pub covariance: Option<Matrix6<f64>>,
    /// The solver that produced the returned pose, and how it ended.
    pub refinement: Refinement,
    /// Stage timings.
    pub timings: Timings,
    /// The method's own diagnostics.
    pub details: D,
}

/// Details that know their method.
pub trait MethodDetails {
    /// The method that produced them (never [`Method::Auto`]).
    fn method(&self) -> Method;
}

impl<D: MethodDetails> Calibration<D> {
    /// The method that produced it (never [`Method::Auto`]).
    pub fn method(&self) -> Method {
        self.details.method()
    }
}

impl<D: Into<Details>> Calibration<D> {
    /// The same result with its details as the sum of the methods' ([`Details`]).
    pub fn into_any(self) -> Calibration {
        Calibration {
            reference_from_target: self.reference_from_target,
            initial_reference_from_target: self.initial_reference_from_target,
            check: self.check,
            rmse: self.rmse,
            inliers_reference: self.inliers_reference,
            inliers_target: self.inliers_target,
            covariance: self.covariance,
            refinement: self.refinement,
            timings: self.timings,
            details: self.details.into(),
        }
    }
}

/// The result of [`calibrate_planes`](super::planes::calibrate_planes).
pub type PlanarCalibration = Calibration<PlanarDetails>;
/// The result of [`calibrate_poles`](super::poles::calibrate_poles).
pub type PoleCalibration = Calibration<PoleDetails>;
/// The result of [`calibrate_targetless`](super::targetless::calibrate_targetless).
pub type TargetlessCalibration = Calibration<TargetlessDetails>;

/// The details of one of the methods.
// One per calibration, moved a few times: boxing the larger variants buys nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Details {
    /// The corner method's.
    Planes(PlanarDetails),
    /// The pole method's.
    Poles(PoleDetails),
    /// The targetless method's.
    Targetless(TargetlessDetails),
}

impl MethodDetails for Details {
    fn method(&self) -> Method {
        match self {
            Details::Planes(_) => Method::Planes,
            Details::Poles(_) => Method::Poles,
            Details::Targetless(_) => Method::Targetless,
        }
    }
}

macro_rules! details_of {
    ($details:ty, $variant:ident) => {
        impl MethodDetails for $details {
            fn method(&self) -> Method {
                Method::$variant
            }
        }
        impl From<$details> for Details {
            fn from(d: $details) -> Details {
                Details::$variant(d)
            }
        }
    };
}
details_of!(PlanarDetails, Planes);
details_of!(PoleDetails, Poles);
details_of!(TargetlessDetails, Targetless);

/// Which solver produced the returned pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// None: the closed-form estimate is the result (the corner method with `refine` off).
    ClosedForm,
    /// Levenberg–Marquardt ([`crate::lm`]) on the matched planes or pole axes.
    LevenbergMarquardt,
    /// Point-to-plane ICP on the whole clouds (the targetless method's last step).
    Icp,
    /// The targetless method kept its verified hypothesis: the refinements moved it into space
    /// the other sensor saw through.
    Verification,
    /// The check's local re-alignment on the whole scene (step 7 of the pole method, taken when
    /// the check refused the pole pose).
    SceneAlignment,
}

impl Solver {
    /// `"closed_form"`, `"levenberg_marquardt"`, `"icp"`, `"verification"` or
    /// `"scene_alignment"`.
    pub fn name(self) -> &'static str {
        match self {
            Solver::ClosedForm => "closed_form",
            Solver::LevenbergMarquardt => "levenberg_marquardt",
            Solver::Icp => "icp",
            Solver::Verification => "verification",
            Solver::SceneAlignment => "scene_alignment",
        }
    }
}

/// The solver that produced the returned pose, and how it ended.
///
/// Solvers that are not iterations of their own ([`Solver::ClosedForm`],
/// [`Solver::Verification`], [`Solver::SceneAlignment`], which the check passed) report
/// `converged`, 0 iterations, a NaN cost and the termination `"none"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refinement {
    /// The solver.
    pub solver: Solver,
    /// `false` only when the solver's iteration cap ran out first.
    pub converged: bool,
    /// Iterations run.
    pub iterations: usize,
    /// Final cost `1/2 sum rho(r^2)` of Levenberg–Marquardt; NaN for the other solvers (ICP
    /// reports its correspondences instead: the targetless details' `icp`).
    pub cost: f64,
    /// Why the solver stopped: a [`Termination`](crate::lm::Termination) name for
    /// Levenberg–Marquardt, `"step_tolerance"` or `"max_iterations"` for ICP, `"none"` for the
    /// others.
    pub termination: &'static str,
}

impl Refinement {
    /// A solver without iterations of its own.
    pub(crate) fn without_iterations(solver: Solver) -> Self {
        Refinement {
            solver,
            converged: true,
            iterations: 0,
            cost: f64::NAN,
            termination: "none",
        }
    }

    /// Levenberg–Marquardt's report, or the closed form when it did not run.
    pub(crate) fn from_lm(report: Option<&LmReport>) -> Self {
        report.map_or(Self::without_iterations(Solver::ClosedForm), |r| {
            Refinement {
                solver: Solver::LevenbergMarquardt,
                converged: r.converged(),
                iterations: r.iterations,
                cost: r.final_cost,
                termination: r.termination.as_str(),
            }
        })
    }

    /// An ICP run.
    pub(crate) fn from_icp(icp: &IcpResult) -> Self {
        Refinement {
            solver: Solver::Icp,
            converged: icp.converged,
            iterations: icp.iterations,
            cost: f64::NAN,
            termination: if icp.converged {
                "step_tolerance"
            } else {
                "max_iterations"
            },
        }
    }
}
