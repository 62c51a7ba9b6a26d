//! Point-to-plane ICP between two whole clouds, robust to partial overlap, and the helpers it
//! needs: voxel downsampling and per-point normals.
//!
//! * [`voxel_downsample`] replaces the points of each cubic voxel by their centroid (and says
//!   which voxel every input point fell in), which evens out the density of a spinning LiDAR
//!   (dense near the sensor, sparse far away) and bounds the work.
//! * [`SurfaceCloud`] is the reference side of ICP: the points, a k-d tree over them (the
//!   [`kiddo`] crate's immutable tree: pure Rust, no threads of its own) and a unit normal per point from the
//!   principal axes of its 10 nearest neighbours. Points whose neighbourhood is
//!   not flat (foliage, edges: surface variation above 0.08) get no normal and
//!   are never used as correspondences. The targetless method's final ICP gives points whose
//!   neighbours lie along one scan line of a plane it segmented that plane's normal instead
//!   (`PlaneNormals`): a line has no normal of its own.
//! * [`point_to_plane_icp`] aligns a target cloud to it. Each iteration pairs every sampled target
//!   point with its nearest reference point within the current correspondence distance, weights
//!   the point-to-plane residual `n . (T p - q)` with a Cauchy loss at a third of that distance,
//!   and takes one Gauss–Newton step on SE(3) (left perturbation, as in [`crate::lm`]). The
//!   distance shrinks geometrically from `max_distance` to `min_distance`, so the start may be a
//!   few decimetres off, and points without a counterpart (the part of each scan the other
//!   sensor does not see) find none and drop out: that is what makes it robust to partial
//!   overlap.
//!
//! The result carries the information matrix `J^T W J` at the solution. Its translation block
//! `sum w n n^T` says how well each direction of translation is constrained: along a corridor
//! (floor and parallel walls only) every normal is perpendicular to the corridor and the block is
//! singular; [`IcpResult::weakest_translation`] reports the weakest direction and its share of the
//! information, which the targetless calibration uses to refuse such scenes.
//!
//! Everything is deterministic: samples are a fixed stride, sums run in fixed chunks
//! ([`crate::lm::accumulate`]), and the same input gives the same output on any thread count.
//!
//! ```
//! use lidarcal::icp::{point_to_plane_icp, IcpOptions, SurfaceCloud};
//! use lidarcal::geometry::se3_exp;
//! use nalgebra::{Isometry3, Point3, Vector6};
//!
//! // Three orthogonal planar patches (an open box corner), 10 cm grid.
//! let mut points = Vec::new();
//! for i in 0..40 {
//!     for j in 0..40 {
//!         let (a, b) = (i as f64 * 0.1, j as f64 * 0.1);
//!         points.push(Point3::new(a, b, 0.0));
//!         points.push(Point3::new(a, 0.0, b));
//!         points.push(Point3::new(0.0, a, b));
//!     }
//! }
//! let truth = se3_exp(&Vector6::new(0.05, -0.03, 0.02, 0.01, -0.02, 0.015));
//! let target: Vec<_> = points.iter().map(|p| truth.inverse() * p).collect();
//! let reference = SurfaceCloud::new(points)?;
//! let result = point_to_plane_icp(&reference, &target, &Isometry3::identity(), &IcpOptions::default())?;
//! let error = result.pose.inverse() * truth;
//! assert!(error.translation.vector.norm() < 1e-3 && error.rotation.angle() < 1e-3);
//! # Ok::<(), lidarcal::Error>(())
//! ```

use std::sync::OnceLock;

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, SymmetricEigen, Vector3, Vector6};
use std::num::NonZeroUsize;

use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;

use crate::error::{ensure_finite, Error, FailureKind, Result};
use crate::fit::Moments;
use crate::geometry::se3_exp;
use crate::grid::NeighbourGrid;
use crate::lm::{accumulate, Accumulator, Loss, NormalEquations};

/// Neighbours used to estimate each reference point's normal.
const NORMAL_NEIGHBOURS: usize = 10;
/// Cell side (metres) of a [`SurfaceCloud`]'s hash grid: it answers nearest-neighbour queries up
/// to this radius (every gate of the check and the verification but the first step of a ground
/// sweep's screening, which the k-d tree serves). On a 40k-voxel street scan 1 m cells answered
/// 30 cm and 1 m queries in 144 and 228 ns (the k-d tree: 354 and 582), and 50 cm cells, which
/// reach only 50 cm, in 134 ns.
const GRID_CELL: f64 = 1.0;
/// Radius (metres) of the grid's search for a point's ten neighbours: at the 10 cm voxels of the
/// check and the verification, they lie within about 20 cm on any surface.
const NEIGHBOURHOOD_BOUND: f64 = 0.5;
/// Largest surface variation `l0 / (l0 + l1 + l2)` of a neighbourhood that still counts as a
/// surface (0 for a perfect plane, 1/3 for isotropic scatter).
const MAX_SURFACE_VARIATION: f64 = 0.08;
/// A neighbourhood is a scan line when its middle principal value is under this share of its
/// largest (its points lie along one line) ...
const LINE_SPREAD: f64 = 0.02;
/// ... and, for [`PlaneNormals`], it lies in a plane when its direction is within this angle
/// (radians, 15 degrees) of the plane.
const LINE_IN_PLANE: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// Largest voxel count along one axis accepted by [`voxel_downsample`].
const MAX_VOXEL_INDEX: f64 = 1e12;

/// Centroids of the points of each cubic voxel of side `voxel`, in the order the voxels are first
/// met, and for every input point the index of its voxel (its centroid) in the output.
///
/// Errors for a non-positive or non-finite voxel, non-finite points, or a voxel so small that the
/// coordinates overflow.
pub fn voxel_downsample(
    points: &[Point3<f64>],
    voxel: f64,
) -> Result<(Vec<Point3<f64>>, Vec<usize>)> {
    downsample(points, voxel, true)
}

/// The centroids of [`voxel_downsample`] alone (no per-point voxel index: 8 bytes a point less).
pub(crate) fn voxel_centroids(points: &[Point3<f64>], voxel: f64) -> Result<Vec<Point3<f64>>> {
    downsample(points, voxel, false).map(|(centroids, _)| centroids)
}

/// [`voxel_downsample`], with each point's voxel only when `owners`.
fn downsample(
    points: &[Point3<f64>],
    voxel: f64,
    owners: bool,
) -> Result<(Vec<Point3<f64>>, Vec<usize>)> {
    if !(voxel.is_finite() && voxel > 0.0) {
        return Err(Error::InvalidInput(format!(
            "voxel size must be finite and positive, got {voxel}"
        )));
    }
    ensure_finite("points", points.iter().flat_map(|p| p.coords.iter()))?;
    let cell = |p: &Point3<f64>| -> Result<[i64; 3]> {
        let mut key = [0i64; 3];
        for (k, c) in key.iter_mut().zip(p.coords.iter()) {
            let f = crate::geometry::floor(c / voxel);
            if f.abs() > MAX_VOXEL_INDEX {
                return Err(Error::InvalidInput(format!(
                    "coordinate {c} is too large for a voxel of {voxel} m"
                )));
            }
            *k = f as i64;
        }
        Ok(key)
    };
    // Voxel indices within +/-2^20 on every axis (100 km at 10 cm) pack into one u64, which
    // hashes 1.5-2x faster than three; a cloud reaching beyond falls back to the full keys. Both
    // give the same voxels in the same order.
    let packed = group_by_key(points, owners, |p| {
        let key = cell(p)?;
        Ok(key
            .iter()
            .all(|k| k.unsigned_abs() < PACKED_HALF_RANGE)
            .then(|| {
                key.iter().fold(0u64, |acc, &k| {
                    (acc << PACKED_BITS) | (k + PACKED_HALF_RANGE as i64) as u64
                })
            }))
    })?;
    let (Grouped { mut sums, counts }, owner) = match packed {
        Some(grouped) => grouped,
        None => group_by_key(points, owners, |p| cell(p).map(Some))?
            .ok_or_else(|| Error::Numerical("voxel keys could not be formed".into()))?,
    };
    for (sum, n) in sums.iter_mut().zip(&counts) {
        *sum /= (*n).max(1) as f64;
    }
    // The means become the centroids in place (same layout: no second buffer), then give back
    // the room reserved for a voxel per point.
    let mut centroids: Vec<Point3<f64>> = sums.into_iter().map(Point3::from).collect();
    centroids.shrink_to_fit();
    Ok((centroids, owner))
}

/// Most voxels the map of [`voxel_downsample`] has room for from the start.
const MAX_VOXEL_CAPACITY: usize = 1 << 17;
/// Bits per axis of a packed voxel key in [`voxel_downsample`].
const PACKED_BITS: u32 = 21;
/// Voxel indices below this in magnitude fit a packed key.
const PACKED_HALF_RANGE: u64 = 1 << (PACKED_BITS - 1);

/// Per-voxel coordinate sums and point counts, in the order the voxels are first met. Two
/// buffers rather than one of pairs: the sums then turn into the centroids in place.
struct Grouped {
    sums: Vec<Vector3<f64>>,
    counts: Vec<usize>,
}

/// The [`Grouped`] sums of the voxels and (when `owners`) each point's voxel, for the voxel key
/// `key_of` gives each point; `None` as soon as it gives `None`.
fn group_by_key<K: std::hash::Hash + Eq + Clone>(
    points: &[Point3<f64>],
    owners: bool,
    key_of: impl Fn(&Point3<f64>) -> Result<Option<K>>,
) -> Result<Option<(Grouped, Vec<usize>)>> {
    // Room for a voxel per point, as many as a sparse scan can have (the Hesai P64's 106k points
    // make 75k voxels): growing the map and the sums from half that made this 4x slower (6 vs
    // 1.5 ms), most of it reallocating. But not for more than 2^17 voxels: a 1M-point scan's
    // map then starts at 4.5 MB and its sums at 4 MB (32 bytes a voxel) instead of 36 and 32,
    // and they grow only if they need to.
    let capacity = points.len().min(MAX_VOXEL_CAPACITY);
    let mut index: rustc_hash::FxHashMap<K, usize> =
        rustc_hash::FxHashMap::with_capacity_and_hasher(capacity, Default::default());
    let mut sums: Vec<Vector3<f64>> = Vec::with_capacity(capacity);
    let mut counts: Vec<usize> = Vec::with_capacity(capacity);
    let mut owner = Vec::with_capacity(if owners { points.len() } else { 0 });
    // The voxel of the previous point: a scan's consecutive returns often share one (neighbours
    // along a ring at short range), and that skips the map.
    let mut last: Option<(K, usize)> = None;
    for p in points {
        let Some(key) = key_of(p)? else {
            return Ok(None);
        };
        let slot = match &last {
            Some((k, slot)) if *k == key => *slot,
            _ => {
                let next = sums.len();
                let slot = *index.entry(key.clone()).or_insert(next);
                if slot == next {
                    sums.push(Vector3::zeros());
                    counts.push(0);
                }
                last = Some((key, slot));
                slot
            }
        };
        if let (Some(s), Some(n)) = (sums.get_mut(slot), counts.get_mut(slot)) {
            *s += p.coords;
            *n += 1;
        }
        if owners {
            owner.push(slot);
        }
    }
    Ok(Some((Grouped { sums, counts }, owner)))
}

/// The k-d tree of a [`SurfaceCloud`]: `f64` coordinates, `u32` point indices, 3-D, 32 points per
/// leaf. Built 4x faster than the R*-tree it replaced (3 vs 12 ms for 75k points) and queried
/// 2-4x faster.
type Tree = ImmutableKdTree<f64, u32, 3, 32>;

/// The reference side of ICP: points, a k-d tree and per-point normals (see the module docs).
///
/// Normals are computed lazily, the first time a point is used as a correspondence, and cached:
/// ICP touches only the part of the reference the target overlaps. A normal is a pure function of
/// the point's neighbourhood, so the order of first use (thread scheduling) changes nothing.
#[derive(Debug, Clone)]
pub struct SurfaceCloud {
    points: Vec<Point3<f64>>,
    normals: Vec<OnceLock<Option<Vector3<f64>>>>,
    tree: Tree,
    /// For the bounded nearest-neighbour queries within its reach (most of them).
    grid: NeighbourGrid,
}

impl SurfaceCloud {
    /// Indexes `points` and estimates their normals. Needs at least 10 finite
    /// points, and fewer than 2^32.
    pub fn new(points: Vec<Point3<f64>>) -> Result<Self> {
        ensure_finite("points", points.iter().flat_map(|p| p.coords.iter()))?;
        if points.len() < NORMAL_NEIGHBOURS {
            return Err(Error::InvalidInput(format!(
                "a surface cloud needs at least {NORMAL_NEIGHBOURS} points, got {}",
                points.len()
            )));
        }
        if u32::try_from(points.len()).is_err() {
            return Err(Error::InvalidInput(format!(
                "a surface cloud holds fewer than 2^32 points, got {}",
                points.len()
            )));
        }
        // The tree wants plain arrays: the points become them in place and back (same layout),
        // rather than through a copy of the cloud.
        let coordinates: Vec<[f64; 3]> = points.into_iter().map(|p| p.coords.into()).collect();
        let (tree, grid) = crate::join(
            || Tree::new_from_slice(&coordinates),
            || NeighbourGrid::new(&coordinates, GRID_CELL),
        );
        let points: Vec<Point3<f64>> = coordinates.into_iter().map(Point3::from).collect();
        let normals = (0..points.len()).map(|_| OnceLock::new()).collect();
        Ok(SurfaceCloud {
            points,
            normals,
            tree,
            grid,
        })
    }

    /// The moments of the 10 nearest points of `p`.
    fn neighbourhood(&self, p: &Point3<f64>) -> Moments {
        let mut m = Moments::new(*p);
        let k = NonZeroUsize::new(NORMAL_NEIGHBOURS).unwrap_or(NonZeroUsize::MIN);
        // The grid finds the ten nearest, nearest first, when they lie within its bound (on
        // any surface at the check's 10 cm voxels); the k-d tree's unbounded search, several
        // times slower, serves sparse clouds.
        match self
            .grid
            .nearest_k(p, NORMAL_NEIGHBOURS, NEIGHBOURHOOD_BOUND)
        {
            Some(near) => {
                for (i, _) in near {
                    if let Some(q) = self.points.get(i) {
                        m.add(q);
                    }
                }
            }
            None => {
                let q = [p.x, p.y, p.z];
                for n in self.tree.nearest_n::<SquaredEuclidean>(&q, k) {
                    if let Some(q) = self.points.get(n.item as usize) {
                        m.add(q);
                    }
                }
            }
        }
        m
    }

    /// The normal of a neighbourhood with these principal axes (smallest first), or `None` when
    /// it is not a surface.
    fn surface_normal(values: &[f64; 3], vectors: &[Vector3<f64>; 3]) -> Option<Vector3<f64>> {
        let total = values[0] + values[1] + values[2];
        (total > 0.0 && values[0] <= MAX_SURFACE_VARIATION * total).then_some(vectors[0])
    }

    fn estimate_normal(&self, p: &Point3<f64>) -> Option<Vector3<f64>> {
        let (values, vectors) = self.neighbourhood(p).principal_axes();
        Self::surface_normal(&values, &vectors)
    }

    /// The local thickness at point `i`: the RMS distance of its neighbourhood from the
    /// neighbourhood's best-fitting plane (noise and curvature together), or `None` where the
    /// neighbourhood is not a surface (no [`normal`](Self::normal)). Independent of any pose, it
    /// is the scale a residual against this surface should be compared with.
    pub fn thickness(&self, i: usize) -> Option<f64> {
        let m = self.neighbourhood(self.points.get(i)?);
        let (values, vectors) = m.principal_axes();
        // One neighbourhood search for both: the normal is cached as `normal(i)` would.
        let normal = Self::surface_normal(&values, &vectors);
        (*self.normals.get(i)?.get_or_init(|| normal))?;
        Some((values[0] / m.weight().max(1.0)).sqrt())
    }

    /// The points.
    pub fn points(&self) -> &[Point3<f64>] {
        &self.points
    }

    /// The unit normal of point `i`, or `None` where the neighbourhood is not a surface.
    pub fn normal(&self, i: usize) -> Option<Vector3<f64>> {
        let (cell, p) = (self.normals.get(i)?, self.points.get(i)?);
        *cell.get_or_init(|| self.estimate_normal(p))
    }

    /// The normal of point `i` as [`PlaneNormals`] has it: its plane's where its neighbours lie
    /// along a scan line in that plane, its own otherwise. `planes` must be built on this cloud.
    pub(crate) fn normal_on_planes(&self, i: usize, planes: &PlaneNormals) -> Option<Vector3<f64>> {
        let (Some(Some(plane)), Some(cell)) = (planes.plane.get(i), planes.normals.get(i)) else {
            return self.normal(i);
        };
        *cell.get_or_init(|| {
            let (values, vectors) = self.neighbourhood(self.points.get(i)?).principal_axes();
            // One neighbourhood search for both: the own normal is cached as `normal(i)` would.
            let own = self.normals.get(i)?;
            let own = *own.get_or_init(|| Self::surface_normal(&values, &vectors));
            let along_line = values[1] < LINE_SPREAD * values[2];
            if along_line && vectors[2].dot(plane).abs() < LINE_IN_PLANE.sin() {
                Some(*plane)
            } else {
                own
            }
        })
    }

    /// The nearest point to `q` within `max_distance`: `(index, squared distance)`.
    pub fn nearest(&self, q: &Point3<f64>, max_distance: f64) -> Option<(usize, f64)> {
        if self.grid.reaches(max_distance) {
            return self.grid.nearest(q, max_distance);
        }
        // A search bounded by the distance: an unbounded nearest-neighbour query from a point far
        // from the cloud (most of a partial overlap) walks much of the tree.
        self.tree
            .nearest_n_within::<SquaredEuclidean>(
                &[q.x, q.y, q.z],
                max_distance * max_distance,
                NonZeroUsize::MIN,
                true,
            )
            .first()
            .map(|n| (n.item as usize, n.distance))
    }

    /// Whether some point lies within `distance` of `q`.
    pub fn any_within(&self, q: &Point3<f64>, distance: f64) -> bool {
        self.nearest(q, distance).is_some()
    }

    /// Fraction of `points`, mapped by `pose` (`reference_from_points`), with a reference point
    /// within `distance`.
    pub fn overlap(&self, points: &[Point3<f64>], pose: &Isometry3<f64>, distance: f64) -> f64 {
        if points.is_empty() {
            return 0.0;
        }
        let near = points
            .iter()
            .filter(|p| self.any_within(&(pose * *p), distance))
            .count();
        near as f64 / points.len() as f64
    }
}

/// The normals of a [`SurfaceCloud`]'s points that lie along one scan line of a known plane,
/// replaced by the plane's.
///
/// A far wall seen by a 16-beam unit is a few scan rings half a metre apart, a few centimetres
/// between points along each. The ten nearest neighbours of such a point lie along its ring, and
/// the smallest axis of a line is any direction across it: the estimated normal is arbitrary in
/// the plane perpendicular to the ring, and a point-to-plane fit on it pulls the pose along the
/// wall (16-beam corners settled 10-40 cm off, vertically). A plane fitted over metres (the
/// targetless segmentation) knows the wall's normal; a point whose neighbours lie along a line
/// within 15 degrees of that plane takes it. Other points keep their own normal.
#[derive(Debug)]
pub(crate) struct PlaneNormals {
    /// For each point of the cloud, the normal of the plane it is an inlier of.
    plane: Vec<Option<Vector3<f64>>>,
    normals: Vec<OnceLock<Option<Vector3<f64>>>>,
}

impl PlaneNormals {
    /// The planes of `cloud`: each a unit normal and the indices of its points (a point in several
    /// keeps the first). Indices outside the cloud are ignored.
    pub(crate) fn new<'a>(
        cloud: &SurfaceCloud,
        planes: impl IntoIterator<Item = (Vector3<f64>, &'a [usize])>,
    ) -> Self {
        let n = cloud.points.len();
        let mut plane = vec![None; n];
        for (normal, indices) in planes {
            for &i in indices {
                if let Some(slot @ None) = plane.get_mut(i) {
                    *slot = Some(normal);
                }
            }
        }
        PlaneNormals {
            plane,
            normals: (0..n).map(|_| OnceLock::new()).collect(),
        }
    }
}

/// Options of [`point_to_plane_icp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpOptions {
    /// Correspondence distance of the first iteration (metres).
    pub max_distance: f64,
    /// Correspondence distance it shrinks to (metres).
    pub min_distance: f64,
    /// Factor applied to the distance after each iteration (in `(0, 1]`).
    pub shrink: f64,
    /// Upper bound on iterations.
    pub max_iterations: usize,
    /// Target points used (at most, by a fixed stride). The default, 20 000, is every point of
    /// a side unit's scan after 0.1 m downsampling: on the real road pairs a 2000-point stride
    /// sample left the pose up to 1.5 cm and 0.1 degrees from the all-points optimum.
    pub samples: usize,
    /// Stop once the distance has reached `min_distance` and a step moves less than this
    /// (tangent norm: metres and radians together). The default, `1e-4` (0.1 mm, 0.006
    /// degrees), is where the steps stop being progress and become correspondences switching.
    pub step_tolerance: f64,
}

impl Default for IcpOptions {
    fn default() -> Self {
        IcpOptions {
            max_distance: 1.0,
            min_distance: 0.2,
            shrink: 0.7,
            max_iterations: 30,
            samples: 20_000,
            step_tolerance: 1e-4,
        }
    }
}

impl IcpOptions {
    fn validate(&self) -> Result<()> {
        let ok = self.min_distance.is_finite()
            && self.min_distance > 0.0
            && self.max_distance.is_finite()
            && self.max_distance >= self.min_distance
            && self.shrink > 0.0
            && self.shrink <= 1.0
            && self.step_tolerance >= 0.0
            && self.max_iterations > 0
            && self.samples > 0;
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidInput(format!(
                "ICP options out of range: need 0 < min_distance <= max_distance, shrink in (0, 1], \
                 step_tolerance >= 0, max_iterations and samples >= 1; got {self:?}"
            )))
        }
    }
}

/// The result of [`point_to_plane_icp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpResult {
    /// The refined `reference_from_target`.
    pub pose: Isometry3<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// `true` when the last step was below the tolerance at the final distance.
    pub converged: bool,
    /// Correspondences of the last iteration.
    pub correspondences: usize,
    /// Fraction of the sampled target points with a correspondence at the final distance.
    pub fitness: f64,
    /// Root-mean-square point-to-plane residual of the correspondences (metres).
    pub rmse: f64,
    /// `J^T W J` at the solution (tangent `[rho; phi]`, left perturbation), Cauchy-weighted.
    pub information: Matrix6<f64>,
    /// Covariance `s^2 (J^T W J)^-1` with `s^2` the weighted residual variance; `None` when the
    /// information matrix is singular.
    pub covariance: Option<Matrix6<f64>>,
}

/// The weakest direction of a symmetric positive semi-definite 3x3 block and its share of the
/// trace: `(unit direction, smallest eigenvalue / trace)`.
pub fn weakest_direction(block: &Matrix3<f64>) -> (Vector3<f64>, f64) {
    let eig = SymmetricEigen::new(*block);
    let mut k = 0;
    for i in 1..3 {
        if eig.eigenvalues[i] < eig.eigenvalues[k] {
            k = i;
        }
    }
    let trace = block.trace();
    let share = if trace > 0.0 {
        (eig.eigenvalues[k] / trace).max(0.0)
    } else {
        0.0
    };
    (eig.eigenvectors.column(k).into_owned(), share)
}

/// The weakest directions of a pose's information matrix (tangent `[rho; phi]`): the
/// translation block's ([`weakest_direction`]) and the rotation block's.
pub fn weakest_directions(information: &Matrix6<f64>) -> [(Vector3<f64>, f64); 2] {
    [0, 3].map(|at| weakest_direction(&information.fixed_view::<3, 3>(at, at).into_owned()))
}

impl IcpResult {
    /// The least-constrained direction of translation (reference frame) and its share of the
    /// translation information (`0` = unconstrained, `1/3` = isotropic).
    pub fn weakest_translation(&self) -> (Vector3<f64>, f64) {
        weakest_directions(&self.information)[0]
    }

    /// The least-constrained rotation axis and its share of the rotation information.
    pub fn weakest_rotation(&self) -> (Vector3<f64>, f64) {
        weakest_directions(&self.information)[1]
    }
}

/// A target point and, for the normal-compatibility gate, its own surface normal.
type Sample = (Point3<f64>, Option<Vector3<f64>>);

/// Normal equations of point-to-plane correspondences, with their count and the loss-weighted
/// sum of squared residuals (ICP here, the odometry's registration and a drive's map alignment).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct PlaneSums {
    pub(crate) ne: NormalEquations,
    pub(crate) matched: usize,
    pub(crate) squared: f64,
    pub(crate) weight: f64,
}

impl Accumulator for PlaneSums {
    fn merge(&mut self, o: &Self) {
        self.ne.merge(&o.ne);
        self.matched += o.matched;
        self.squared += o.squared;
        self.weight += o.weight;
    }
}

impl PlaneSums {
    /// Adds the residual `r = n . (q - m)` of a correspondence with unit normal `n` at the mapped
    /// point `q`, for a left perturbation of the pose that maps it (Jacobian row `[n, q x n]`).
    #[inline]
    pub(crate) fn add(&mut self, r: f64, n: &Vector3<f64>, q: &Vector3<f64>, loss: Loss) {
        let c = q.cross(n);
        self.ne
            .add(r, &Vector6::new(n.x, n.y, n.z, c.x, c.y, c.z), loss);
        self.matched += 1;
        let w = loss.weight(r * r);
        self.squared += w * r * r;
        self.weight += w;
    }

    /// The loss-weighted root-mean-square residual (0 without correspondences).
    pub(crate) fn rmse(&self) -> f64 {
        if self.weight > 0.0 {
            (self.squared / self.weight).sqrt()
        } else {
            0.0
        }
    }
}

/// The reference side of one ICP: the cloud, and the plane normals its scan-line points take
/// ([`PlaneNormals`]) or none.
#[derive(Clone, Copy)]
struct Surface<'a> {
    cloud: &'a SurfaceCloud,
    planes: Option<&'a PlaneNormals>,
}

impl<'a> Surface<'a> {
    fn new(cloud: &'a SurfaceCloud, planes: Option<&'a PlaneNormals>) -> Self {
        Surface { cloud, planes }
    }

    fn normal(&self, i: usize) -> Option<Vector3<f64>> {
        match self.planes {
            Some(planes) => self.cloud.normal_on_planes(i, planes),
            None => self.cloud.normal(i),
        }
    }
}

fn linearise(
    reference: Surface<'_>,
    samples: &[Sample],
    pose: &Isometry3<f64>,
    distance: f64,
    min_normal_cos: f64,
) -> PlaneSums {
    let loss = Loss::Cauchy {
        scale: distance / 3.0,
    };
    let mut sums: PlaneSums = accumulate(samples, |(p, own), acc: &mut PlaneSums| {
        let q = pose * p;
        let Some((i, _)) = reference.cloud.nearest(&q, distance) else {
            return;
        };
        let (Some(n), Some(r_point)) = (reference.normal(i), reference.cloud.points.get(i)) else {
            return;
        };
        if let Some(own) = own {
            if (pose.rotation * own).dot(&n).abs() < min_normal_cos {
                return;
            }
        }
        acc.add(n.dot(&(q - r_point)), &n, &q.coords, loss);
    });
    sums.ne.symmetrize();
    sums
}

/// Aligns `target` (points in the target frame) to `reference`, starting from `initial`
/// (`reference_from_target`). See the module docs.
///
/// Errors: [`Error::InvalidInput`] for bad options or points; [`Error::Calibration`] when fewer
/// than 6 correspondences are found (the clouds do not overlap at this start).
pub fn point_to_plane_icp(
    reference: &SurfaceCloud,
    target: &[Point3<f64>],
    initial: &Isometry3<f64>,
    options: &IcpOptions,
) -> Result<IcpResult> {
    point_to_plane_icp_on_planes(reference, None, target, initial, options)
}

/// [`point_to_plane_icp`], with the normals of `planes` (built on `reference`) for the
/// reference's scan-line points when given.
pub(crate) fn point_to_plane_icp_on_planes(
    reference: &SurfaceCloud,
    planes: Option<&PlaneNormals>,
    target: &[Point3<f64>],
    initial: &Isometry3<f64>,
    options: &IcpOptions,
) -> Result<IcpResult> {
    let samples = stride_samples(target, options)?;
    let surface = Surface::new(reference, planes);
    icp_on_samples(surface, &samples, initial, options, 0.0)
}

/// At most `options.samples` of `target`, by a fixed stride, without normals, once the options
/// and the points are checked.
fn stride_samples(target: &[Point3<f64>], options: &IcpOptions) -> Result<Vec<Sample>> {
    options.validate()?;
    ensure_finite("target", target.iter().flat_map(|p| p.coords.iter()))?;
    let stride = target.len().div_ceil(options.samples).max(1);
    Ok(target.iter().step_by(stride).map(|p| (*p, None)).collect())
}

/// What [`point_to_plane_icp`] reports, at `pose` as it stands: no step is taken, pairs are
/// sought within `options.min_distance`, `iterations` is 0 and `converged` true. For comparing a
/// pose found otherwise (a plane fit) with an ICP result on the same terms.
///
/// Errors: [`Error::InvalidInput`] for bad options or points.
pub fn point_to_plane_fit(
    reference: &SurfaceCloud,
    target: &[Point3<f64>],
    pose: &Isometry3<f64>,
    options: &IcpOptions,
) -> Result<IcpResult> {
    point_to_plane_fit_on_planes(reference, None, target, pose, options)
}

/// [`point_to_plane_fit`], with the normals of `planes` (built on `reference`) for the
/// reference's scan-line points when given.
pub(crate) fn point_to_plane_fit_on_planes(
    reference: &SurfaceCloud,
    planes: Option<&PlaneNormals>,
    target: &[Point3<f64>],
    pose: &Isometry3<f64>,
    options: &IcpOptions,
) -> Result<IcpResult> {
    let samples = stride_samples(target, options)?;
    Ok(summarise(
        Surface::new(reference, planes),
        &samples,
        pose,
        options.min_distance,
        0.0,
        0,
        true,
    ))
}

/// [`point_to_plane_icp`] with the target as a [`SurfaceCloud`] too: a pair counts only when
/// the two points' normals (the target's turned by the pose) are within `max_normal_angle`
/// (radians) of parallel, and target points without a normal are left out. Near the crease of a
/// sparse corner the nearest reference point often lies on the other surface; the gate keeps
/// such pairs out (a 16-beam corner otherwise pulled the pose 14 cm from the truth). Target
/// points farther than `2 max_distance` from the reference at `initial` are left out as well.
pub fn point_to_plane_icp_with_normals(
    reference: &SurfaceCloud,
    target: &SurfaceCloud,
    initial: &Isometry3<f64>,
    options: &IcpOptions,
    max_normal_angle: f64,
) -> Result<IcpResult> {
    if !(max_normal_angle.is_finite()
        && (0.0..=std::f64::consts::FRAC_PI_2).contains(&max_normal_angle))
    {
        return Err(Error::InvalidInput(format!(
            "max_normal_angle must be in [0, pi/2] rad, got {max_normal_angle}"
        )));
    }
    options.validate()?;
    let points = target.points();
    let stride = points.len().div_ceil(options.samples).max(1);
    // Points with no reference point within twice the first correspondence distance at the
    // start stay out: only a pose moving by more than that distance could pair them, and the
    // search for their nearest point and their normal is most of the work on a partial overlap.
    let reach = 2.0 * options.max_distance;
    // Each sample's test and normal are independent (a normal is a pure function of the
    // cloud): in parallel, in order. Computing the target's normals is most of a short ICP.
    let indices: Vec<usize> = (0..points.len()).step_by(stride).collect();
    let samples: Vec<Sample> = crate::par_map(&indices, |&i| {
        let p = *points.get(i)?;
        reference.any_within(&(initial * p), reach).then_some(())?;
        Some((p, Some(target.normal(i)?)))
    })
    .into_iter()
    .flatten()
    .collect();
    icp_on_samples(
        Surface::new(reference, None),
        &samples,
        initial,
        options,
        max_normal_angle.cos(),
    )
}

fn icp_on_samples(
    reference: Surface<'_>,
    samples: &[Sample],
    initial: &Isometry3<f64>,
    options: &IcpOptions,
    min_normal_cos: f64,
) -> Result<IcpResult> {
    // `options` were validated by the public entry points (the sample stride divides by them).
    let mut pose = *initial;
    let mut distance = options.max_distance;
    let mut iterations = 0;
    let mut converged = false;
    let mut last_step = None;
    while iterations < options.max_iterations {
        iterations += 1;
        let sums = linearise(reference, samples, &pose, distance, min_normal_cos);
        if sums.matched < 6 {
            return Err(Error::calibration(
                FailureKind::TooFewFeatures,
                format!(
                    "ICP found only {} correspondences within {distance:.2} m: the clouds do not \
                 overlap at this pose",
                    sums.matched
                ),
            ));
        }
        let h = sums.ne.hessian;
        // A floor on the damping keeps unobserved directions (a corridor) from moving.
        let floor = 1e-9 * h.diagonal().amax().max(f64::MIN_POSITIVE);
        let damped = h + Matrix6::identity() * floor;
        let Some(step) = damped.cholesky().map(|c| c.solve(&(-sums.ne.gradient))) else {
            return Err(Error::Numerical(
                "ICP normal equations are not positive definite".into(),
            ));
        };
        if !step.iter().all(|x| x.is_finite()) {
            return Err(Error::Numerical("ICP produced a non-finite step".into()));
        }
        pose = se3_exp(&step) * pose;
        let at_final = distance <= options.min_distance;
        // Settled: the step is under the tolerance, or, with plane normals for the scan lines,
        // it undoes the previous one. A scan-line point takes its plane's normal and its
        // neighbour off the line keeps its own, so a pair moving from one to the other can make
        // the pairs alternate between two sets and the pose between two places a fraction of a
        // millimetre apart (a 16-beam corner, adversarial 183: 0.25 mm, for 95 iterations).
        let undone = reference.planes.is_some()
            && last_step
                .is_some_and(|last: Vector6<f64>| (step + last).norm() < options.step_tolerance);
        if at_final && (step.norm() < options.step_tolerance || undone) {
            converged = true;
            break;
        }
        last_step = at_final.then_some(step);
        distance = (distance * options.shrink).max(options.min_distance);
    }
    Ok(summarise(
        reference,
        samples,
        &pose,
        distance,
        min_normal_cos,
        iterations,
        converged,
    ))
}

/// The [`IcpResult`] at `pose`: correspondences within `distance`, information, covariance.
fn summarise(
    reference: Surface<'_>,
    samples: &[Sample],
    pose: &Isometry3<f64>,
    distance: f64,
    min_normal_cos: f64,
    iterations: usize,
    converged: bool,
) -> IcpResult {
    let sums = linearise(reference, samples, pose, distance, min_normal_cos);
    let information = sums.ne.hessian;
    let dof = sums.weight - 6.0;
    let covariance = if dof > 0.0 {
        let sigma2 = sums.squared / dof;
        information.cholesky().map(|c| c.inverse() * sigma2)
    } else {
        None
    };
    IcpResult {
        pose: *pose,
        iterations,
        converged,
        correspondences: sums.matched,
        fitness: sums.matched as f64 / samples.len().max(1) as f64,
        rmse: sums.rmse(),
        information,
        covariance,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxel_downsample_keeps_order_and_owners() {
        let pts = vec![
            Point3::new(0.05, 0.05, 0.0),
            Point3::new(1.05, 0.0, 0.0),
            Point3::new(0.15, 0.05, 0.0),
        ];
        let (c, owner) = voxel_downsample(&pts, 0.5).unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(owner, vec![0, 1, 0]);
        assert!((c[0].x - 0.1).abs() < 1e-12);
        assert!(voxel_downsample(&pts, 0.0).is_err());
        assert!(voxel_downsample(&[Point3::new(f64::NAN, 0.0, 0.0)], 1.0).is_err());
    }

    #[test]
    fn packed_and_full_voxel_keys_give_the_same_voxels() {
        // Negative and positive coordinates near the voxel edges; one point 200 km out (beyond the
        // packed keys at 10 cm) sends the whole cloud down the full-key path.
        let near: Vec<Point3<f64>> = (0..500)
            .map(|i| {
                let f = i as f64;
                Point3::new(
                    (f * 0.37).sin() * 3.0,
                    (f * 0.11).cos() * -2.0,
                    f * 0.013 - 3.0,
                )
            })
            .collect();
        let (packed, packed_owner) = voxel_downsample(&near, 0.1).unwrap();
        let mut with_far = near.clone();
        with_far.push(Point3::new(-2.0e5, 0.0, 0.0));
        let (full, full_owner) = voxel_downsample(&with_far, 0.1).unwrap();
        assert_eq!(full.len(), packed.len() + 1);
        assert_eq!(&full[..packed.len()], &packed[..]);
        assert_eq!(&full_owner[..near.len()], &packed_owner[..]);
        assert!(packed.len() > 100 && packed.len() < near.len());
    }

    #[test]
    fn corridor_translation_is_reported_unconstrained() {
        // Floor and two parallel walls along x: no information along x.
        let mut pts = Vec::new();
        for i in 0..200 {
            for j in 0..20 {
                let x = i as f64 * 0.1;
                let s = j as f64 * 0.1;
                pts.push(Point3::new(x, s - 1.0, 0.0));
                pts.push(Point3::new(x, -1.0, s));
                pts.push(Point3::new(x, 1.0, s));
            }
        }
        let reference = SurfaceCloud::new(pts.clone()).unwrap();
        let r = point_to_plane_icp(
            &reference,
            &pts,
            &Isometry3::identity(),
            &IcpOptions::default(),
        )
        .unwrap();
        let (dir, share) = r.weakest_translation();
        // Not exactly 0: along the floor-wall crease a 10-neighbour patch can be thinner along
        // x than across the crease, and its "normal" then points along x. What matters is that
        // the share is far below the targetless refusal threshold (1 %).
        assert!(share < 1e-3, "{share}");
        assert!(dir.x.abs() > 0.999, "{dir}");
    }

    #[test]
    fn duplicate_points_are_indexed() {
        // Many copies of one point (a scan of a sensor's own housing, replayed frames) beside a
        // plane: the k-d tree takes them, neighbour queries answer, nothing panics.
        let mut pts = vec![Point3::new(1.0, 1.0, 1.0); 2000];
        for i in 0..20 {
            for j in 0..20 {
                pts.push(Point3::new(i as f64 * 0.1, j as f64 * 0.1, 0.0));
            }
        }
        let cloud = SurfaceCloud::new(pts).unwrap();
        let (i, d2) = cloud.nearest(&Point3::new(1.0, 1.0, 1.05), 0.1).unwrap();
        assert!(i < 2000 && (d2 - 0.0025).abs() < 1e-12);
        assert!(
            cloud.normal(0).is_none(),
            "a heap of one point has no surface"
        );
        assert!(cloud.normal(2000 + 21).is_some());
        assert!(!cloud.any_within(&Point3::new(5.0, 5.0, 5.0), 1.0));
    }

    #[test]
    fn fit_reports_the_pose_as_it_stands() {
        // An open box corner; the fit at a pose 5 cm off reports that pose, a worse RMS than at
        // the truth, and the same statistics ICP reports once it has converged there.
        let mut pts = Vec::new();
        for i in 0..30 {
            for j in 0..30 {
                let (a, b) = (i as f64 * 0.1, j as f64 * 0.1);
                pts.push(Point3::new(a, b, 0.0));
                pts.push(Point3::new(a, 0.0, b));
                pts.push(Point3::new(0.0, a, b));
            }
        }
        let reference = SurfaceCloud::new(pts.clone()).unwrap();
        let options = IcpOptions::default();
        let off = Isometry3::translation(0.03, 0.04, 0.0);
        let at_off = point_to_plane_fit(&reference, &pts, &off, &options).unwrap();
        assert_eq!(at_off.pose, off);
        assert_eq!((at_off.iterations, at_off.converged), (0, true));
        let icp = point_to_plane_icp(&reference, &pts, &off, &options).unwrap();
        assert!(icp.converged && icp.pose.translation.vector.norm() < 1e-3);
        let at_truth = point_to_plane_fit(&reference, &pts, &icp.pose, &options).unwrap();
        assert!(
            at_off.rmse > 10.0 * at_truth.rmse,
            "{} {}",
            at_off.rmse,
            at_truth.rmse
        );
        assert!((at_truth.rmse - icp.rmse).abs() < 1e-9);
        assert_eq!(at_truth.correspondences, icp.correspondences);
        // Bad options are refused as by ICP.
        let bad = IcpOptions {
            samples: 0,
            ..options
        };
        assert!(point_to_plane_fit(&reference, &pts, &off, &bad).is_err());
    }

    #[test]
    fn zero_samples_is_an_error_not_a_division_by_zero() {
        let pts: Vec<_> = (0..100)
            .map(|i| Point3::new((i % 10) as f64, (i / 10) as f64, 0.0))
            .collect();
        let surface = SurfaceCloud::new(pts.clone()).unwrap();
        let none = IcpOptions {
            samples: 0,
            ..IcpOptions::default()
        };
        let start = Isometry3::identity();
        assert!(matches!(
            point_to_plane_icp(&surface, &pts, &start, &none),
            Err(Error::InvalidInput(_))
        ));
        assert!(matches!(
            point_to_plane_icp_with_normals(&surface, &surface, &start, &none, 0.5),
            Err(Error::InvalidInput(_))
        ));
    }

    #[test]
    fn bad_options_and_disjoint_clouds() {
        let pts: Vec<_> = (0..100)
            .map(|i| Point3::new((i % 10) as f64, (i / 10) as f64, 0.0))
            .collect();
        let reference = SurfaceCloud::new(pts.clone()).unwrap();
        let bad = IcpOptions {
            min_distance: 2.0,
            max_distance: 1.0,
            ..IcpOptions::default()
        };
        assert!(point_to_plane_icp(&reference, &pts, &Isometry3::identity(), &bad).is_err());
        let far: Vec<_> = pts.iter().map(|p| p + Vector3::z() * 50.0).collect();
        assert!(matches!(
            point_to_plane_icp(
                &reference,
                &far,
                &Isometry3::identity(),
                &IcpOptions::default()
            ),
            Err(Error::Calibration { .. })
        ));
        assert!(SurfaceCloud::new(pts[..3].to_vec()).is_err());
    }

    #[test]
    fn scan_line_points_take_their_planes_normal() {
        // A wall at x = 5 seen as three rings 0.5 m apart, 5 cm between points along each, with
        // range noise (x, 5 mm) above the beam's wobble (z, 2 mm): each point's ten neighbours
        // lie along its ring, and their smallest axis is the vertical, not the wall's normal.
        // The ground's points, inliers of a plane too but spread over it (no line), keep theirs
        // even when that plane's normal is off.
        let wobble = |k: usize, a: f64| a * ((k * 7919) % 13) as f64 / 6.0 - a;
        let mut points = Vec::new();
        for ring in 0..3 {
            for k in 0..80 {
                let y = -2.0 + 0.05 * k as f64;
                let z = 0.5 * ring as f64 + wobble(k + ring, 0.002);
                points.push(Point3::new(5.0 + wobble(k * 3 + ring, 0.005), y, z));
            }
        }
        let wall: Vec<usize> = (0..points.len()).collect();
        for i in 0..20 {
            for j in 0..20 {
                points.push(Point3::new(i as f64 * 0.2, j as f64 * 0.2 - 2.0, -1.5));
            }
        }
        let ground: Vec<usize> = (wall.len()..points.len()).collect();
        let tilted = Vector3::new(0.2, 0.0, 1.0).normalize();
        let cloud = SurfaceCloud::new(points).unwrap();
        let planes = PlaneNormals::new(
            &cloud,
            [(Vector3::x(), wall.as_slice()), (tilted, ground.as_slice())],
        );
        let on_ring = 80 + 40;
        let own = cloud.normal(on_ring).unwrap();
        assert!(own.z.abs() > 0.9, "own normal {own:?}");
        let taken = cloud.normal_on_planes(on_ring, &planes).unwrap();
        assert_eq!(taken, Vector3::x());
        let on_ground = wall.len() + 210;
        let kept = cloud.normal_on_planes(on_ground, &planes).unwrap();
        assert_eq!(Some(kept), cloud.normal(on_ground));
        assert!(kept.z.abs() > 0.999, "ground normal {kept:?}");
    }
}
