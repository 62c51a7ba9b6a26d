//! Step 1-2 of the targetless pipeline: downsampling and the planes of each cloud (region growing
//! over flat patches, plus sequential RANSAC for the few scan lines a tilted unit puts on a facade).

use nalgebra::{Point3, Vector3};

use super::super::planes::estimate_threshold;
use super::options::TargetlessOptions;
use crate::error::{Error, Result};
use crate::fit::Moments;
use crate::geometry::{cell_key, Plane};
use crate::icp::voxel_downsample;
use crate::ransac::plane::ransac_plane;
use crate::ransac::RansacOptions;

/// Bounds of the inlier threshold taken from the noise estimate (metres). Road scenes are not
/// flat (camber, kerbs, pavements): when the estimate fails or exceeds the upper bound, the upper
/// bound is used.
pub(super) const ESTIMATED_THRESHOLD_RANGE: (f64, f64) = (0.03, 0.1);
/// Side of the cubic cells whose points form the local patches of the plane segmentation (m).
pub(super) const PATCH_SIZE: f64 = 1.0;
/// Fewest (downsampled) points of a patch.
const PATCH_MIN_POINTS: usize = 5;
/// A patch is flat when the RMS distance of its points to their plane is under this fraction of
/// the inlier threshold ...
const PATCH_MAX_THICKNESS: f64 = 0.8;
/// ... and its points spread at least this far (metres, RMS) along its second axis (not a line).
const PATCH_MIN_SPREAD: f64 = 0.1;
/// A neighbouring patch joins a growing plane when its normal is within this angle (radians,
/// 10 degrees) of the plane's ...
const GROW_ANGLE: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// ... and its centroid within this many inlier thresholds of the plane.
const GROW_OFFSET: f64 = 2.0;
/// A segmented plane within this angle (radians, 5 degrees) ...
const MERGE_ANGLE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// ... and offset (metres) of a larger one is another part of the same surface (an uneven road)
/// and is not kept as a plane of its own.
const MERGE_OFFSET: f64 = 0.3;
/// RANSAC hypotheses per sequentially extracted plane.
const PLANE_RANSAC_ITERATIONS: usize = 1000;
/// Points (at most, by a fixed stride) each sequential RANSAC run samples and scores; the
/// inliers are then collected from all remaining points.
const SEQUENTIAL_SAMPLES: usize = 15_000;
/// Smallest extent of a plane along its second in-plane axis (metres).
const MIN_PLANE_WIDTH: f64 = 1.0;

/// A plane of one cloud with what the matching uses.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneFeature {
    /// The plane, normal toward the sensor.
    pub plane: Plane,
    /// Indices of its inliers in the downsampled cloud.
    pub voxels: Vec<usize>,
    /// Centroid of the inliers.
    pub centroid: Point3<f64>,
    /// Extent of the inliers along their two principal in-plane axes (metres, larger first:
    /// `sqrt(12 l)` of the scatter eigenvalues, the side of a uniform patch).
    pub extent: [f64; 2],
}

/// A downsampled cloud with its planes.
pub(super) struct Prepared {
    pub(super) points: Vec<Point3<f64>>,
    pub(super) owner: Vec<usize>,
    pub(super) threshold: f64,
    pub(super) features: Vec<PlaneFeature>,
}

pub(super) fn prepare(points: &[Point3<f64>], options: &TargetlessOptions) -> Result<Prepared> {
    let (ds, owner) = voxel_downsample(points, options.voxel_size)?;
    let threshold = match options.distance_threshold {
        Some(t) => t,
        None => match estimate_threshold(&ds, options.seed) {
            Ok(t) => t.clamp(ESTIMATED_THRESHOLD_RANGE.0, ESTIMATED_THRESHOLD_RANGE.1),
            Err(Error::Calibration { .. }) => ESTIMATED_THRESHOLD_RANGE.1,
            Err(e) => return Err(e),
        },
    };
    let mut features = segment_planes(&ds, threshold, options.max_planes, options.min_inliers)?;
    let seq = sequential_planes(
        &ds,
        threshold,
        2 * options.max_planes,
        options.min_inliers,
        options.seed,
    )?;
    features.extend(seq);
    let features = distinct(features, 2 * options.max_planes);
    Ok(Prepared {
        points: ds,
        owner,
        threshold,
        features,
    })
}

/// A flat cell of the segmentation.
pub(super) struct Patch {
    pub(super) moments: Moments,
    pub(super) normal: Vector3<f64>,
    pub(super) centroid: Point3<f64>,
    pub(super) indices: Vec<usize>,
}

/// Up to `max_planes` distinct planar surfaces of `points` by region growing over flat local
/// patches (1 m cells, grown where their normals and offsets agree), largest first. Each plane is refitted
/// on its patches' points; its inliers are those within `threshold`.
pub fn segment_planes(
    points: &[Point3<f64>],
    threshold: f64,
    max_planes: usize,
    min_inliers: usize,
) -> Result<Vec<PlaneFeature>> {
    let patches = flat_patches(points, threshold);
    let regions = grow_regions(&patches, threshold)?;
    let mut features: Vec<PlaneFeature> = Vec::new();
    for region in regions {
        features.extend(region_feature(
            points,
            &patches.patches,
            &region,
            threshold,
            min_inliers,
        ));
    }
    Ok(distinct(features, max_planes))
}

/// The flat patches of a cloud with their cells: `patch_of` maps a cell to its patch,
/// `keys[i]` is patch `i`'s cell.
pub(super) struct Patches {
    patches: Vec<Patch>,
    patch_of: std::collections::HashMap<[i64; 3], usize>,
    keys: Vec<[i64; 3]>,
}

/// The flat cells of [`PATCH_SIZE`] of `points` (see [`PATCH_MAX_THICKNESS`],
/// [`PATCH_MIN_SPREAD`]), in the order of their cell keys.
fn flat_patches(points: &[Point3<f64>], threshold: f64) -> Patches {
    let mut cells: std::collections::HashMap<[i64; 3], Vec<usize>> =
        std::collections::HashMap::new();
    for (i, p) in points.iter().enumerate() {
        cells
            .entry(cell_key(&p.coords, PATCH_SIZE))
            .or_default()
            .push(i);
    }
    let mut cell_keys: Vec<[i64; 3]> = cells.keys().copied().collect();
    cell_keys.sort_unstable();
    let mut patches: Vec<Patch> = Vec::new();
    let mut patch_of: std::collections::HashMap<[i64; 3], usize> = std::collections::HashMap::new();
    for key in &cell_keys {
        let Some(indices) = cells.remove(key) else {
            continue;
        };
        if indices.len() < PATCH_MIN_POINTS {
            continue;
        }
        let moments = Moments::from_points(indices.iter().filter_map(|&i| points.get(i)));
        let (values, vectors) = moments.principal_axes();
        let n = moments.weight();
        let thickness = (values[0] / n).sqrt();
        let spread = (values[1] / n).sqrt();
        if thickness > PATCH_MAX_THICKNESS * threshold || spread < PATCH_MIN_SPREAD {
            continue;
        }
        let centroid = moments.mean();
        let mut normal = vectors[0];
        if normal.dot(&centroid.coords) > 0.0 {
            normal = -normal; // toward the sensor
        }
        patch_of.insert(*key, patches.len());
        patches.push(Patch {
            moments,
            normal,
            centroid,
            indices,
        });
    }
    let keys: Vec<[i64; 3]> = {
        let mut v = vec![[0i64; 3]; patches.len()];
        for (k, &i) in &patch_of {
            if let Some(slot) = v.get_mut(i) {
                *slot = *k;
            }
        }
        v
    };
    Patches {
        patches,
        patch_of,
        keys,
    }
}

/// Regions of patches grown from the largest: a neighbouring patch joins when its normal is
/// within [`GROW_ANGLE`] of the region's plane and its centroid within [`GROW_OFFSET`]
/// thresholds of it.
fn grow_regions(patches: &Patches, threshold: f64) -> Result<Vec<Vec<usize>>> {
    let Patches {
        patches,
        patch_of,
        keys: patch_keys,
    } = patches;
    let mut order: Vec<usize> = (0..patches.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(patches[i].indices.len()));
    let mut assigned = vec![false; patches.len()];
    let mut regions: Vec<Vec<usize>> = Vec::new();
    for &seed in &order {
        if assigned[seed] {
            continue;
        }
        assigned[seed] = true;
        let mut region = vec![seed];
        let mut moments = patches[seed].moments;
        let mut plane = Plane::from_point_normal(&patches[seed].centroid, &patches[seed].normal)?;
        let mut queue = std::collections::VecDeque::from([seed]);
        while let Some(current) = queue.pop_front() {
            if let Ok(fit) = moments.plane() {
                plane = fit.plane;
            }
            let [x, y, z] = patch_keys[current];
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(&j) = patch_of.get(&[x + dx, y + dy, z + dz]) else {
                            continue;
                        };
                        if assigned[j] {
                            continue;
                        }
                        let p = &patches[j];
                        let aligned = p.normal.dot(&plane.normal).abs() > GROW_ANGLE.cos();
                        let near =
                            plane.signed_distance(&p.centroid).abs() < GROW_OFFSET * threshold;
                        if aligned && near {
                            assigned[j] = true;
                            region.push(j);
                            merge_moments(&mut moments, &p.moments);
                            queue.push_back(j);
                        }
                    }
                }
            }
        }
        regions.push(region);
    }
    Ok(regions)
}

/// The plane of a region refitted on its patches' points, with its inliers within `threshold`;
/// `None` for fewer than `min_inliers` or no plane.
fn region_feature(
    points: &[Point3<f64>],
    patches: &[Patch],
    region: &[usize],
    threshold: f64,
    min_inliers: usize,
) -> Option<PlaneFeature> {
    let candidates: Vec<usize> = region
        .iter()
        .flat_map(|&r| patches[r].indices.iter().copied())
        .collect();
    if candidates.len() < min_inliers {
        return None;
    }
    let fit = Moments::from_points(candidates.iter().filter_map(|&i| points.get(i)))
        .plane()
        .ok()?;
    let plane = fit.plane.oriented_toward(&Point3::origin());
    let mut voxels: Vec<usize> = candidates
        .into_iter()
        .filter(|&i| {
            points
                .get(i)
                .is_some_and(|p| plane.signed_distance(p).abs() < threshold)
        })
        .collect();
    voxels.sort_unstable();
    if voxels.len() < min_inliers {
        return None;
    }
    feature(points, plane, voxels)
}

/// The largest `max_planes` of `features` that are not within [`MERGE_ANGLE`] and
/// [`MERGE_OFFSET`] of a larger one.
pub(super) fn distinct(mut features: Vec<PlaneFeature>, max_planes: usize) -> Vec<PlaneFeature> {
    features.sort_by_key(|f| std::cmp::Reverse(f.voxels.len()));
    let mut kept: Vec<PlaneFeature> = Vec::new();
    for f in features {
        if kept.len() >= max_planes {
            break;
        }
        let duplicate = kept.iter().any(|k| {
            k.plane.normal.dot(&f.plane.normal) > MERGE_ANGLE.cos()
                && (k.plane.offset - f.plane.offset).abs() < MERGE_OFFSET
        });
        if !duplicate {
            kept.push(f);
        }
    }
    kept
}

/// A plane feature from inlier indices, if it is at least [`MIN_PLANE_WIDTH`] wide.
pub(super) fn feature(
    points: &[Point3<f64>],
    plane: Plane,
    voxels: Vec<usize>,
) -> Option<PlaneFeature> {
    let m = Moments::from_points(voxels.iter().filter_map(|&i| points.get(i)));
    let extent = m.extents();
    (extent[1] >= MIN_PLANE_WIDTH).then(|| PlaneFeature {
        plane,
        voxels,
        centroid: m.mean(),
        extent,
    })
}

/// Up to `count` planes by sequential RANSAC (infinite planes, each run on the points the
/// previous ones left). It finds what the patches miss in sparse clouds: a facade crossed by a
/// few scan lines of a tilted unit.
pub(super) fn sequential_planes(
    points: &[Point3<f64>],
    threshold: f64,
    count: usize,
    min_inliers: usize,
    seed: u64,
) -> Result<Vec<PlaneFeature>> {
    let mut taken = vec![false; points.len()];
    let mut out = Vec::new();
    for run in 0..count {
        let remaining: Vec<usize> = (0..points.len()).filter(|&i| !taken[i]).collect();
        if remaining.len() < min_inliers.max(3) {
            break;
        }
        // RANSAC runs on an even subsample of a large cloud; the inliers are then taken from
        // all remaining points.
        let stride = remaining.len().div_ceil(SEQUENTIAL_SAMPLES).max(1);
        let subset: Vec<Point3<f64>> = remaining
            .iter()
            .step_by(stride)
            .filter_map(|&i| points.get(i).copied())
            .collect();
        let mut options = RansacOptions::new(threshold);
        options.seed = seed.wrapping_add((run as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        options.max_iterations = PLANE_RANSAC_ITERATIONS;
        let found = match ransac_plane(&subset, &options) {
            Ok(f) => f,
            Err(Error::Degenerate(_)) => break,
            Err(e) => return Err(e),
        };
        let voxels: Vec<usize> = remaining
            .iter()
            .copied()
            .filter(|&i| {
                points
                    .get(i)
                    .is_some_and(|p| found.model.signed_distance(p).abs() < threshold)
            })
            .collect();
        if voxels.len() < min_inliers {
            break;
        }
        for &i in &voxels {
            taken[i] = true;
        }
        out.extend(feature(points, found.model, voxels));
    }
    Ok(out)
}

/// Adds the moments `b` into `a` (both shifted to their own origins).
pub(super) fn merge_moments(a: &mut Moments, b: &Moments) {
    // Moments only exposes point accumulation; rebuild `b`'s contribution from its mean and
    // scatter: adding the scatter's principal components as weighted point pairs is exact.
    let n = b.weight();
    if n <= 0.0 {
        return;
    }
    let mean = b.mean();
    let (values, vectors) = b.principal_axes();
    // Two points at mean +- s v with weight n/2 each per axis reproduce the scatter l v v^T
    // when s = sqrt(l / n); the mean is kept and the total weight is 3n, so scale by 1/3.
    for (l, v) in values.iter().zip(vectors.iter()) {
        let s = (l / n).sqrt() * 3f64.sqrt();
        a.add_weighted(&(mean + v * s), n / 6.0);
        a.add_weighted(&(mean - v * s), n / 6.0);
    }
}

/// The planes [`calibrate_targetless`](super::calibrate_targetless) extracts from one cloud (steps 1 and 2 of the module docs)
/// and the inlier threshold used; feature voxel indices refer to the downsampled cloud.
pub fn plane_features(
    points: &[Point3<f64>],
    options: &TargetlessOptions,
) -> Result<(Vec<PlaneFeature>, f64)> {
    options.validate()?;
    check_cloud(points, "input")?;
    let p = prepare(points, options)?;
    Ok((p.features, p.threshold))
}

/// The targetless method's input rules ([`check_cloud`](crate::calib::input::check_cloud)): at
/// least 100 points.
pub(super) fn check_cloud(points: &[Point3<f64>], which: &str) -> Result<()> {
    crate::calib::input::check_cloud(points, which, 100, "the targetless method needs")
}
