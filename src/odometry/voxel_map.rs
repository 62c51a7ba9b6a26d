//! The local map of the odometry: a hash of cubic voxels, each holding up to a fixed number of
//! points with their surface normals, in the world frame (the sensor's first frame).
//!
//! Points come from the frames already registered, downsampled to half a voxel, so a voxel
//! fills from several frames and then stops growing: the map's density is bounded whatever
//! the drive's length. Voxels farther than the sensor's range from its newest position are
//! dropped. A query looks for the nearest map point in the query's voxel and its 26
//! neighbours, as KISS-ICP does.

use nalgebra::{Point3, Vector3};
use rustc_hash::FxHashMap;

use crate::geometry::cell_key;

/// One map point: where it is and the normal of the surface it was sampled from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MapPoint {
    pub(crate) position: Point3<f64>,
    pub(crate) normal: Vector3<f64>,
}

/// The voxel map (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct VoxelMap {
    voxel: f64,
    max_points: usize,
    voxels: FxHashMap<[i64; 3], Vec<MapPoint>>,
}

impl VoxelMap {
    /// An empty map of voxels of side `voxel` (positive) with room for `max_points` (>= 1) each.
    pub(crate) fn new(voxel: f64, max_points: usize) -> Self {
        VoxelMap {
            voxel,
            max_points,
            voxels: FxHashMap::default(),
        }
    }

    /// Whether the map holds no point.
    #[cfg(test)]
    pub(crate) fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// Points held.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.voxels.values().map(Vec::len).sum()
    }

    /// Adds points (world frame) to the voxels they fall in, skipping those whose voxel is full.
    pub(crate) fn add(&mut self, points: impl IntoIterator<Item = MapPoint>) {
        for p in points {
            let cell = self
                .voxels
                .entry(cell_key(&p.position.coords, self.voxel))
                .or_default();
            if cell.len() < self.max_points {
                cell.push(p);
            }
        }
    }

    /// Drops the voxels whose centre lies farther than `radius` from `origin`.
    pub(crate) fn retain_within(&mut self, origin: &Point3<f64>, radius: f64) {
        let voxel = self.voxel;
        let limit = (radius + voxel) * (radius + voxel);
        self.voxels.retain(|k, _| {
            let centre = Vector3::new(
                (k[0] as f64 + 0.5) * voxel,
                (k[1] as f64 + 0.5) * voxel,
                (k[2] as f64 + 0.5) * voxel,
            );
            (centre - origin.coords).norm_squared() <= limit
        });
    }

    /// The nearest map point to `q` within `distance`, searching `q`'s voxel and its 26
    /// neighbours (so a `distance` beyond one voxel may miss a farther point: never a wrong one).
    pub(crate) fn nearest(&self, q: &Point3<f64>, distance: f64) -> Option<&MapPoint> {
        let c = cell_key(&q.coords, self.voxel);
        let mut best: Option<(&MapPoint, f64)> = None;
        let mut bound = distance * distance;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(cell) = self.voxels.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for p in cell {
                        let d = (p.position - q).norm_squared();
                        if d <= bound {
                            bound = d;
                            best = Some((p, d));
                        }
                    }
                }
            }
        }
        best.map(|(p, _)| p)
    }

    /// Every point of the map.
    #[cfg(test)]
    pub(crate) fn points(&self) -> impl Iterator<Item = &MapPoint> {
        self.voxels.values().flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(x: f64, y: f64, z: f64) -> MapPoint {
        MapPoint {
            position: Point3::new(x, y, z),
            normal: Vector3::z(),
        }
    }

    #[test]
    fn voxels_fill_up_and_far_ones_are_dropped() {
        let mut map = VoxelMap::new(1.0, 3);
        map.add((0..10).map(|i| point(0.1 * i as f64 / 10.0, 0.5, 0.5)));
        assert_eq!(map.len(), 3);
        map.add([point(50.0, 0.0, 0.0)]);
        assert_eq!(map.len(), 4);
        map.retain_within(&Point3::origin(), 10.0);
        assert_eq!(map.len(), 3);
        assert!(!map.is_empty());
    }

    #[test]
    fn nearest_matches_brute_force_within_a_voxel() {
        let mut map = VoxelMap::new(1.0, 20);
        let pts: Vec<MapPoint> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.37;
                point(t.sin() * 3.0, (1.3 * t).cos() * 3.0, (0.7 * t).sin())
            })
            .collect();
        map.add(pts.iter().copied());
        let held: Vec<MapPoint> = map.points().copied().collect();
        for i in 0..50 {
            let t = i as f64 * 0.91;
            let q = Point3::new(t.cos() * 2.5, t.sin() * 2.5, 0.2);
            let brute = held
                .iter()
                .map(|p| (p, (p.position - q).norm()))
                .filter(|(_, d)| *d <= 1.0)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let found = map.nearest(&q, 1.0);
            assert_eq!(found.map(|p| p.position), brute.map(|(p, _)| p.position));
        }
    }
}
