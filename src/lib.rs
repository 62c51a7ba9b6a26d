//! # lidarcal
//!
//! Extrinsic calibration between LiDARs: the rigid transform `reference_from_target` that maps a
//! target sensor's points into a reference sensor's frame (`p_ref = R p_tgt + t`), found from what
//! the sensors see, without an initial guess.
//!
//! The calibration methods, in [`calib`]:
//!
//! * [`calib::planes`]: three planar surfaces of a wall corner (Jiao et al., 2019), any mounting.
//! * [`calib::poles`]: two or more poles wrapped in retro-reflective tape (Xue et al., 2019;
//!   cylinder axes).
//! * [`calib::targetless`]: the planes of an ordinary scene (a street), matched without an
//!   initial guess, verified by free-space consistency and refined by point-to-plane ICP.
//! * [`calib::method`]: one entry point, [`calib::calibrate`] ([`calib::Method::Auto`] keeps the
//!   best-fitting method's result).
//! * [`calib::rig`]: several sensors at once, [`calib::calibrate_rig`], made consistent by a pose
//!   graph.
//!
//! and what they are built on:
//!
//! * [`geometry`]: SO(3)/SE(3) exponential and logarithm (accurate near 0 and pi), 4x4
//!   conversions, [`Plane`] and [`Line`].
//! * [`kabsch`](mod@kabsch): weighted Kabsch with the reflection fix and a documented degeneracy test.
//! * [`lm`]: a Levenberg–Marquardt solver on SE(3) with a report (termination reason, `J^T J`).
//! * [`pose_graph`]: Gauss–Newton refinement of an SE(3) pose graph with a fixed reference node,
//!   with options and a report.
//! * [`residuals`]: point-to-plane and point-to-line problems with analytic Jacobians.
//! * [`ransac`]: parallel, deterministic RANSAC for planes and lines; multi-plane extraction.
//! * [`fit`]: plane, line and cylinder fits ([`fit::cylinder::fit_cylinder`] recovers a pole's axis).
//! * [`cluster`]: Euclidean clustering on a hash grid; [`metrics`]: Rényi quadratic entropy.
//! * [`icp`]: voxel downsampling, surface normals and robust point-to-plane ICP.
//! * [`visibility`]: free-space consistency of two scans (range images), which tells a wrong pose
//!   from the truth when point agreement cannot.
//! * `sim` (feature `sim`): a scan simulator (VLP-16, HDL-32E, HDL-64E, OS1-128; walls, boxes,
//!   taped poles, streets) with ground-truth scenes.
//! * [`budget`]: wall-clock limits for the long-running stages.
//! * `io` (feature `io`): PCD, PLY, KITTI `.bin`, `.npy` and CSV/TXT point clouds.
//!
//! ## Features
//! * `parallel` (default): rayon in residual accumulation. Results are bit-identical with or
//!   without it and for any thread count.
//! * `io` (default): point-cloud file formats.
//! * `sim` (default): the scan simulator, `lidarcal::sim` (adds rand_distr).
//! * `python`: the PyO3 extension module (implies `io` and `sim`); only maturin turns it on.
//!
//! With `default-features = false` the crate is the calibration methods and what they are built
//! on, without the simulator or file formats. It depends on nalgebra, rand (with rand_chacha),
//! kiddo, rustc-hash and thiserror only (no rayon, no pyo3), never panics on bad input (every
//! fallible function returns [`Result`]) and holds no global state.
//!
//! ## Quick start: calibrate a simulated corner (feature `sim`)
//! Two VLP-16s at a building corner, the transform found from the three planes without an
//! initial guess, and compared with the simulator's ground truth
//! (`cargo run --example quickstart` prints the errors):
#![cfg_attr(feature = "sim", doc = "```")]
#![cfg_attr(not(feature = "sim"), doc = "```ignore")]
//! use lidarcal::calib::planes::{calibrate_planes, PlanarOptions};
//! use lidarcal::sim::scenes::{corner_scene, CornerOptions};
//! use lidarcal::sim::{BeamModel, Preset};
//! use lidarcal::{Error, FailureKind};
//! use nalgebra::Vector3;
//!
//! // Two walls at 90 degrees and the ground, 4 clutter boxes; the target tilted and turned.
//! let scene = corner_scene(&BeamModel::preset(Preset::Vlp16), &CornerOptions::default())?;
//! let (reference, target) = (scene.reference.positions(), scene.target.positions());
//!
//! // A right-angled corner is a cube corner: a 120-degree turn about its diagonal maps the three
//! // planes onto each other, so without a tie-break the method refuses rather than guess...
//! let refused = calibrate_planes(&reference, &target, &PlanarOptions::default());
//! assert!(matches!(refused, Err(Error::Calibration { kind: FailureKind::Ambiguous, .. })));
//! // ...and `up`, the gravity direction in each sensor's frame, breaks the tie. Both sensors
//! // stand roughly upright (tilts under 10 degrees), so it is +z in both.
//! let options = PlanarOptions {
//!     up: Some((Vector3::z(), Vector3::z())),
//!     ..PlanarOptions::default()
//! };
//! let result = calibrate_planes(&reference, &target, &options)?;
//!
//! let (truth, estimate) = (scene.reference_from_target, result.reference_from_target);
//! let rotation_error_deg = (truth.rotation * estimate.rotation.inverse()).angle().to_degrees();
//! let translation_error_m = (truth.translation.vector - estimate.translation.vector).norm();
//! assert!(rotation_error_deg < 0.05 && translation_error_m < 0.005);
//! # Ok::<(), lidarcal::Error>(())
//! ```
//!
//! ## Example: recover a pose from three planes
//! ```
//! use lidarcal::geometry::{se3_exp, Plane};
//! use lidarcal::lm::{solve, LmOptions, Loss};
//! use lidarcal::residuals::{Frame, PlaneGroup, PointToPlane};
//! use nalgebra::{Isometry3, Point3, Vector3, Vector6};
//!
//! let reference_from_target = se3_exp(&Vector6::new(0.4, -0.3, 0.2, 0.1, 0.05, -0.2));
//! let walls = [(Vector3::x(), -4.0), (Vector3::y(), -3.0), (Vector3::z(), 1.8)];
//! let mut groups = Vec::new();
//! for (normal, offset) in walls {
//!     let plane = Plane::new(normal, offset)?;
//!     let (u, v) = lidarcal::geometry::orthonormal_basis(&plane.normal);
//!     let origin = plane.project(&Point3::origin());
//!     let points = (0..400)
//!         .map(|i| {
//!             let p_ref = origin + u * (i % 20) as f64 * 0.1 + v * (i / 20) as f64 * 0.1;
//!             reference_from_target.inverse() * p_ref // as the target sensor sees it
//!         })
//!         .collect();
//!     groups.push(PlaneGroup { plane, points, frame: Frame::Target });
//! }
//! let problem = PointToPlane::new(groups, Loss::Squared)?;
//! let solution = solve(&problem, &Isometry3::identity(), &LmOptions::default())?;
//! assert!(solution.report.converged());
//! let error = solution.pose.inverse() * reference_from_target;
//! assert!(error.translation.vector.norm() < 1e-9 && error.rotation.angle() < 1e-9);
//! # Ok::<(), lidarcal::Error>(())
//! ```
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod budget;
pub mod calib;
pub mod check;
pub mod cluster;
pub mod error;
pub mod fit;
pub mod geometry;
mod grid;
pub mod icp;
pub mod kabsch;
pub mod lm;
pub mod metrics;
pub mod odometry;
pub mod pose_graph;
pub mod ransac;
pub mod residuals;
pub mod visibility;

#[cfg(feature = "sim")]
pub mod sim;

#[cfg(feature = "io")]
pub mod io;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, FailureKind, Result};

/// Runs `a` and `b` side by side on rayon's pool (feature `parallel`), one after the other
/// without it; the results do not depend on which.
pub(crate) fn join<A, B, RA, RB>(a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (a(), b())
    }
}

/// `f` over `items`, in order, on rayon's pool with the `parallel` feature (one after the other
/// without it); the results do not depend on which.
pub(crate) fn par_map<T: Sync, U: Send>(items: &[T], f: impl Fn(&T) -> U + Sync + Send) -> Vec<U> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        items.iter().map(f).collect()
    }
}

/// The value of `cell`, made by `init` on the first call; an `Err` from `init` is returned and
/// leaves the cell empty (`OnceCell::get_or_try_init` is not stable yet).
pub(crate) fn get_or_try_init<T>(
    cell: &std::cell::OnceCell<T>,
    init: impl FnOnce() -> Result<T>,
) -> Result<&T> {
    if let Some(value) = cell.get() {
        return Ok(value);
    }
    let value = init()?;
    Ok(cell.get_or_init(|| value))
}

/// The README's Rust examples, compiled and run as doctests so they cannot rot. They use the
/// simulator, so they run with feature `sim` (a default feature).
#[doc = include_str!("../README.md")]
#[cfg(all(doctest, feature = "sim"))]
pub struct ReadmeDoctests;
/// The Rust examples of the documentation pages (`docs/`), run as doctests like the README's.
#[doc = include_str!("../docs/rust.md")]
#[cfg(all(doctest, feature = "sim"))]
pub struct RustPageDoctests;
/// The Rust example of `docs/results.md`.
#[doc = include_str!("../docs/results.md")]
#[cfg(all(doctest, feature = "sim"))]
pub struct ResultsPageDoctests;
/// The Rust example of `docs/methods/auto_and_rig.md`.
#[doc = include_str!("../docs/methods/auto_and_rig.md")]
#[cfg(all(doctest, feature = "sim"))]
pub struct AutoAndRigPageDoctests;
pub use geometry::{Line, Plane};
pub use kabsch::{kabsch, KabschSolution};
pub use lm::{LmOptions, LmReport, LmSolution, Loss, Termination};
