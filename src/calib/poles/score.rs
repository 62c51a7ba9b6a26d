//! Steps 5 and 6 of the [module docs](super): each hypothesis solved in closed form, refined on
//! point-to-axis distances and scored.

use nalgebra::{Isometry3, Point3};

use super::hypotheses::*;
use super::options::*;
use crate::budget::Deadline;
use crate::cluster::Grid;
use crate::error::Result;
use crate::geometry::{Line, Plane};
use crate::lm::{solve, LmReport};

/// Unit of the axis RMS term of a hypothesis score (metres).
pub(super) const AXIS_RMS_SCALE: f64 = 0.02;
/// Unit of the ground-normal angle term (radians, 5 degrees).
pub(super) const GROUND_ANGLE_SCALE: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Unit of the ground-offset term (metres).
pub(super) const GROUND_OFFSET_SCALE: f64 = 0.2;
/// Unit of the `1 - overlap` term.
pub(super) const OVERLAP_SCALE: f64 = 0.1;
/// Target points (at most, by a fixed stride) used for the overlap term.
pub(super) const OVERLAP_SAMPLE: usize = 1500;

/// Solves, refines and scores the hypotheses of one pair of clouds.
pub(super) struct Scorer<'a> {
    clouds: &'a Clouds<'a>,
    /// The largest plane of the reference and of the target cloud.
    grounds: [Option<Plane>; 2],
    /// Target points of the overlap term (at most [`OVERLAP_SAMPLE`], by a fixed stride).
    sample: Vec<Point3<f64>>,
    /// The reference points, for the overlap term.
    grid: Grid<'a>,
    options: &'a PoleOptions,
    deadline: &'a Deadline,
}

/// The scored hypotheses in enumeration order, with each one's closed-form start and
/// refinement report.
pub(super) type Scored = (Vec<Hypothesis>, Vec<Isometry3<f64>>, Vec<Option<LmReport>>);

impl<'a> Scorer<'a> {
    /// Samples the target for the overlap term and buckets the reference.
    pub(super) fn new(
        clouds: &'a Clouds<'a>,
        grounds: [Option<Plane>; 2],
        options: &'a PoleOptions,
        deadline: &'a Deadline,
    ) -> Result<Self> {
        let stride = clouds.target.len().div_ceil(OVERLAP_SAMPLE).max(1);
        let sample: Vec<Point3<f64>> = clouds.target.iter().step_by(stride).copied().collect();
        let grid = Grid::new(clouds.reference, options.overlap_distance)?;
        Ok(Scorer {
            clouds,
            grounds,
            sample,
            grid,
            options,
            deadline,
        })
    }

    /// Every base match of [`base_matches`] solved, refined and scored (in parallel with the
    /// `parallel` feature); the first error in enumeration order is returned.
    pub(super) fn score_all(&self, bases: &[[(usize, usize, i8); 2]]) -> Result<Scored> {
        let evaluated = crate::par_map(bases, |b| self.evaluate(b));
        let mut hypotheses = Vec::with_capacity(evaluated.len());
        let mut starts = Vec::with_capacity(evaluated.len());
        let mut reports = Vec::with_capacity(evaluated.len());
        for e in evaluated {
            let (h, s, r) = e?;
            hypotheses.push(h);
            starts.push(s);
            reports.push(r);
        }
        Ok((hypotheses, starts, reports))
    }

    /// One base match: the closed form on its two poles, extended by proximity to further poles
    /// (and solved again on all of them), refined and scored.
    pub(super) fn evaluate(
        &self,
        b: &[(usize, usize, i8); 2],
    ) -> Result<(Hypothesis, Isometry3<f64>, Option<LmReport>)> {
        let (clouds, options) = (self.clouds, self.options);
        let (ground_ref, ground_tgt) = (self.grounds[0], self.grounds[1]);
        let (sample, grid) = (&self.sample, &self.grid);
        self.deadline.check("the pole hypotheses")?;
        let pairs: Vec<(Line, Line)> = b
            .iter()
            .map(|&(i, k, s)| {
                (
                    clouds.poles_ref[i].axis,
                    signed_axis(&clouds.poles_tgt[k], s),
                )
            })
            .collect();
        let start = closed_form(&pairs)?;
        let matches = extend_matches(b, &start, clouds);
        let start = if matches.len() > 2 {
            let pairs: Vec<(Line, Line)> = matches
                .iter()
                .map(|&(i, k, s)| {
                    (
                        clouds.poles_ref[i].axis,
                        signed_axis(&clouds.poles_tgt[k], s),
                    )
                })
                .collect();
            closed_form(&pairs)?
        } else {
            start
        };
        let problem = point_to_axis_problem(clouds, &matches, options.loss)?;
        let solution = solve(&problem, &start, &options.lm)?;
        let pose = solution.pose;
        let rms = axis_rms(&problem, &pose);
        let (ground_angle, ground_offset) = match (ground_ref, ground_tgt) {
            (Some(gr), Some(gt)) => {
                let mapped = gt.transformed(&pose);
                let angle = mapped.normal.dot(&gr.normal).clamp(-1.0, 1.0).acos();
                (Some(angle), Some((mapped.offset - gr.offset).abs()))
            }
            _ => (None, None),
        };
        let near = sample
            .iter()
            .filter(|p| grid.any_within(&(pose * *p), options.overlap_distance))
            .count();
        let overlap = near as f64 / sample.len().max(1) as f64;
        let score = rms / AXIS_RMS_SCALE
            + ground_angle.map_or(0.0, |a| a / GROUND_ANGLE_SCALE)
            + ground_offset.map_or(0.0, |d| d / GROUND_OFFSET_SCALE)
            + (1.0 - overlap) / OVERLAP_SCALE;
        Ok((
            Hypothesis {
                matches,
                reference_from_target: pose,
                axis_rms: rms,
                ground_angle,
                ground_offset,
                overlap,
                score,
            },
            start,
            Some(solution.report),
        ))
    }
}
