//! A uniform hash grid for fixed-radius neighbour search, and Euclidean clustering on it.
//!
//! [`Grid`] buckets points into cubic cells of side `cell` (a std `HashMap` from the integer cell
//! coordinates to the indices of its points). All points within `cell` of a query lie in the 27
//! cells around the query's cell, so a fixed-radius query costs the points of those cells; for a
//! fixed radius and a bounded density that is O(1), and building the grid is O(N).
//!
//! Why our own grid rather than a kd-tree crate (kiddo, kdtree): the only queries we need are
//! fixed-radius ones at one radius per grid (the clustering tolerance, the overlap distance of the
//! hypothesis scores, the truncation of the RQE kernel), for which a hash grid is as fast as a
//! tree and needs about 100 lines; it adds no dependency to the `default-features = false` build
//! that embedded users compile, and its output does not depend on any crate's tie-breaking.
//!
//! [`euclidean_clusters`] joins points closer than the tolerance (single linkage) by a breadth-first
//! search over the grid. The output is deterministic: clusters are ordered by their smallest point
//! index and list their points in ascending index order, whatever the hash map's iteration order.
//!
//! ```
//! use lidarcal::cluster::euclidean_clusters;
//! use nalgebra::Point3;
//! let mut pts: Vec<_> = (0..10).map(|i| Point3::new(0.1 * i as f64, 0.0, 0.0)).collect();
//! pts.extend((0..5).map(|i| Point3::new(5.0, 0.1 * i as f64, 0.0)));
//! let clusters = euclidean_clusters(&pts, 0.15)?;
//! assert_eq!(clusters.len(), 2);
//! assert_eq!(clusters[0], (0..10).collect::<Vec<_>>());
//! assert_eq!(clusters[1], (10..15).collect::<Vec<_>>());
//! # Ok::<(), lidarcal::Error>(())
//! ```

use std::collections::{HashMap, VecDeque};
use std::ops::ControlFlow;

use nalgebra::Point3;

use crate::budget::Deadline;
use crate::error::{Error, Result};

/// Largest number of cells along one axis a grid accepts (cell coordinates must fit an `i64` with
/// room for the neighbour offsets; this also refuses absurdly small cells for huge extents).
const MAX_CELL_INDEX: f64 = 1e15;

/// A uniform hash grid over a point set (see the module docs).
#[derive(Debug, Clone)]
pub struct Grid<'a> {
    points: &'a [Point3<f64>],
    cell: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

impl<'a> Grid<'a> {
    /// Buckets `points` into cells of side `cell` metres. Errors for a non-positive or non-finite
    /// cell, non-finite points, or a cell so small that the coordinates overflow.
    pub fn new(points: &'a [Point3<f64>], cell: f64) -> Result<Self> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(Error::InvalidInput(format!(
                "grid cell size must be finite and positive, got {cell}"
            )));
        }
        crate::error::ensure_points("points", points.iter())?;
        let mut cells: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            let key = Self::key_of(p, cell)?;
            cells.entry(key).or_default().push(i);
        }
        Ok(Grid {
            points,
            cell,
            cells,
        })
    }

    fn key_of(p: &Point3<f64>, cell: f64) -> Result<[i64; 3]> {
        let mut key = [0i64; 3];
        for (k, c) in key.iter_mut().zip(p.coords.iter()) {
            let f = crate::geometry::floor(c / cell);
            if f.abs() > MAX_CELL_INDEX {
                return Err(Error::InvalidInput(format!(
                    "coordinate {c} is too large for a grid of cell size {cell}"
                )));
            }
            *k = f as i64;
        }
        Ok(key)
    }

    /// The cell side.
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// The indexed points.
    pub fn points(&self) -> &'a [Point3<f64>] {
        self.points
    }

    /// Calls `f(index, squared_distance)` for every indexed point within `radius` of `q`
    /// (`radius <= cell`; larger radii are clamped to the cell). Points of non-finite queries or
    /// queries outside the grid's coordinate range are not visited.
    pub fn for_each_within<F: FnMut(usize, f64)>(&self, q: &Point3<f64>, radius: f64, mut f: F) {
        // The visitor never breaks, so the walk always runs to the end.
        let _ = self.visit_within(q, radius, |i, d2| {
            f(i, d2);
            ControlFlow::Continue(())
        });
    }

    /// Whether any indexed point lies within `radius` (at most the cell) of `q`.
    pub fn any_within(&self, q: &Point3<f64>, radius: f64) -> bool {
        self.visit_within(q, radius, |_, _| ControlFlow::Break(()))
            .is_break()
    }

    /// Calls `f(index, squared distance)` for the indexed points within `radius` (clamped to the
    /// cell) of `q`, from the 27 cells around `q`'s, until `f` breaks; nothing for a query outside
    /// the grid's range. Plain loops: this is the hot path of clustering and RQE.
    fn visit_within<F: FnMut(usize, f64) -> ControlFlow<()>>(
        &self,
        q: &Point3<f64>,
        radius: f64,
        mut f: F,
    ) -> ControlFlow<()> {
        let Ok(key) = Self::key_of(q, self.cell) else {
            return ControlFlow::Continue(());
        };
        let r2 = radius.min(self.cell).powi(2);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let k = [key[0] + dx, key[1] + dy, key[2] + dz];
                    if let Some(idx) = self.cells.get(&k) {
                        for &i in idx {
                            let d2 = (self.points[i] - q).norm_squared();
                            if d2 <= r2 {
                                f(i, d2)?;
                            }
                        }
                    }
                }
            }
        }
        ControlFlow::Continue(())
    }
}

/// Single-linkage Euclidean clusters: two points closer than `tolerance` share a cluster.
///
/// Returns every cluster (singletons included) as ascending point indices, clusters ordered by
/// their smallest index. O(N) for a fixed tolerance and bounded density.
pub fn euclidean_clusters(points: &[Point3<f64>], tolerance: f64) -> Result<Vec<Vec<usize>>> {
    euclidean_clusters_until(points, tolerance, &Deadline::new(None))
}

/// Points expanded between two checks of the deadline in [`euclidean_clusters_until`].
const DEADLINE_STRIDE: usize = 4096;

/// [`euclidean_clusters`] that fails once `deadline` passes. A tolerance that joins a dense cloud
/// into one cluster makes the search quadratic in the points of a cell (seconds for 100k points,
/// tens of minutes for millions).
pub fn euclidean_clusters_until(
    points: &[Point3<f64>],
    tolerance: f64,
    deadline: &Deadline,
) -> Result<Vec<Vec<usize>>> {
    let grid = Grid::new(points, tolerance)?;
    let mut label = vec![usize::MAX; points.len()];
    let mut clusters = Vec::new();
    let mut queue = VecDeque::new();
    let mut expanded = 0usize;
    for seed in 0..points.len() {
        if label[seed] != usize::MAX {
            continue;
        }
        let id = clusters.len();
        label[seed] = id;
        let mut members = vec![seed];
        queue.push_back(seed);
        while let Some(i) = queue.pop_front() {
            expanded += 1;
            if expanded.is_multiple_of(DEADLINE_STRIDE) {
                deadline.check("clustering of the bright points")?;
            }
            grid.for_each_within(&points[i], tolerance, |j, _| {
                if label[j] == usize::MAX {
                    label[j] = id;
                    members.push(j);
                    queue.push_back(j);
                }
            });
        }
        members.sort_unstable();
        clusters.push(members);
    }
    Ok(clusters)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_query_matches_brute_force() {
        let pts: Vec<Point3<f64>> = (0..500)
            .map(|i| {
                let f = i as f64;
                Point3::new(
                    (f * 0.37).sin() * 2.0,
                    (f * 0.11).cos() * 2.0,
                    (f * 0.07).sin(),
                )
            })
            .collect();
        let grid = Grid::new(&pts, 0.3).unwrap();
        for q in pts.iter().step_by(7) {
            let mut found = Vec::new();
            grid.for_each_within(q, 0.3, |i, _| found.push(i));
            found.sort_unstable();
            let brute: Vec<usize> = (0..pts.len())
                .filter(|&i| (pts[i] - q).norm() <= 0.3)
                .collect();
            assert_eq!(found, brute);
            assert!(grid.any_within(q, 0.3));
        }
        assert!(!grid.any_within(&Point3::new(100.0, 0.0, 0.0), 0.3));
    }

    #[test]
    fn clusters_are_chains_and_deterministic() {
        // Two chains with 0.1 spacing, interleaved in index order, 1 m apart.
        let mut pts = Vec::new();
        for i in 0..20 {
            pts.push(Point3::new(0.1 * i as f64, 0.0, 0.0));
            pts.push(Point3::new(0.1 * i as f64, 1.0, 0.0));
        }
        pts.push(Point3::new(10.0, 10.0, 10.0));
        let c = euclidean_clusters(&pts, 0.15).unwrap();
        assert_eq!(c.len(), 3);
        assert_eq!(c[0], (0..20).map(|i| 2 * i).collect::<Vec<_>>());
        assert_eq!(c[1], (0..20).map(|i| 2 * i + 1).collect::<Vec<_>>());
        assert_eq!(c[2], vec![40]);
        assert!(euclidean_clusters(&pts, 0.0).is_err());
        assert!(euclidean_clusters(&pts, f64::NAN).is_err());
        let mut bad = pts.clone();
        bad[3].x = f64::NAN;
        assert!(euclidean_clusters(&bad, 0.1).is_err());
        assert!(euclidean_clusters(&[], 0.1).unwrap().is_empty());
    }
}
