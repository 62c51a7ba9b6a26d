//! The RANSAC loop: batched, parallel MSAC scoring, local optimisation, adaptive stopping.

use nalgebra::Point3;

use super::sampler::draw_batch;
use super::{inliers, rms, Cloud, Estimator, RansacOptions, RansacResult};
use crate::error::{Error, Result};

/// Most points the hypothesis search (scoring, local optimisation, adaptive stopping) runs on.
/// Larger clouds are searched on a fixed-stride subset: the inlier ratio, and so the ranking of
/// hypotheses, is the same; the final support and least-squares refit use every point.
pub(super) const MAX_SEARCH_POINTS: usize = 32_768;

/// Hypotheses per batch. Fixed, so the sequence of batches (and the result) never depends on the
/// number of threads; large enough to keep both cores busy, small enough that adaptive stopping
/// overshoots by little.
const BATCH: usize = 32;

/// Models scored together in one pass over the data by the kernels.
pub const GROUP: usize = 8;

/// The MSAC score of a model: truncated quadratic cost and inlier count.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Score {
    /// `sum_i min(d_i^2, t^2)`; lower is better.
    pub cost: f64,
    /// Points with `d_i < t` (0 when the scorer was asked not to count).
    pub inliers: usize,
}

/// Hypotheses needed to draw an all-inlier sample with probability `confidence`, given `inliers`
/// of `n` points and samples of `s` points, capped at `cap`.
pub fn required_hypotheses(
    inliers: usize,
    n: usize,
    s: usize,
    confidence: f64,
    cap: usize,
) -> usize {
    if n == 0 {
        return cap;
    }
    let w = inliers as f64 / n as f64;
    let ws = w.powi(s as i32);
    if ws >= 1.0 {
        return 1;
    }
    let denominator = (-ws).ln_1p(); // ln(1 - w^s) < 0, accurate for small w^s
    if denominator >= 0.0 {
        return cap;
    }
    let k = ((1.0 - confidence).ln() / denominator).ceil();
    if k.is_finite() && k < cap as f64 {
        (k as usize).max(1)
    } else {
        cap
    }
}

/// Scores `models` in groups of [`GROUP`], in parallel with the `parallel` feature. The result is
/// in model order and identical for any thread count.
pub fn score_models<E: Estimator>(
    estimator: &E,
    cloud: &Cloud<'_>,
    models: &[E::Model],
    threshold: f64,
    count_inliers: bool,
) -> Vec<Score> {
    let score_group = |group: &[E::Model]| {
        let mut out = [Score::default(); GROUP];
        estimator.score(
            cloud,
            group,
            threshold,
            count_inliers,
            &mut out[..group.len()],
        );
        out[..group.len()].to_vec()
    };
    #[cfg(feature = "parallel")]
    let groups: Vec<Vec<Score>> = {
        use rayon::prelude::*;
        models.par_chunks(GROUP).map(score_group).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let groups: Vec<Vec<Score>> = models.chunks(GROUP).map(score_group).collect();
    groups.into_iter().flatten().collect()
}

/// Refits `model` on its inliers while that lowers the MSAC cost, at most `rounds` times.
/// Returns the model and its score, with the inlier count taken from the exact `f64` test.
fn local_optimization<E: Estimator>(
    estimator: &E,
    cloud: &Cloud<'_>,
    mut model: E::Model,
    mut score: Score,
    options: &RansacOptions,
    point_tests: &mut u64,
) -> (E::Model, Score) {
    let points = cloud.points();
    let threshold = options.distance_threshold;
    let mut support = inliers(estimator, points, &model, threshold);
    for _ in 0..options.local_optimization_rounds {
        let Some(refit) = estimator.refit(points, &support) else {
            break;
        };
        let mut out = [Score::default()];
        estimator.score(cloud, &[refit], threshold, false, &mut out);
        *point_tests += cloud.len() as u64;
        if out[0].cost < score.cost {
            model = refit;
            score.cost = out[0].cost;
            support = inliers(estimator, points, &model, threshold);
        } else {
            break;
        }
    }
    score.inliers = support.len();
    (model, score)
}

/// Runs RANSAC with `estimator` on `points`.
///
/// Errors: [`Error::InvalidInput`] for bad options, non-finite points or fewer points than a
/// minimal sample; [`Error::Degenerate`] when the points determine no model (e.g. collinear points
/// for a plane) or every sample drawn was degenerate.
pub fn ransac<E: Estimator>(
    estimator: &E,
    points: &[Point3<f64>],
    options: &RansacOptions,
) -> Result<RansacResult<E::Model>> {
    options.validate()?;
    let s = E::SAMPLE_SIZE;
    let n = points.len();
    if n < s {
        return Err(Error::InvalidInput(format!(
            "a {} needs at least {s} points, got {n}",
            E::NAME
        )));
    }
    crate::error::ensure_points("points", points.iter())?;
    // The search runs on at most MAX_SEARCH_POINTS points (a fixed stride through the cloud); the
    // final support and least-squares refit use every point.
    let search_points = search_points(points);
    let threshold = options.distance_threshold;
    let found = search(estimator, &search_points, options)?;
    Ok(found.finish(estimator, points, |model| {
        inliers(estimator, points, model, threshold)
    }))
}

/// The points a RANSAC search runs on: `points` itself, or every `stride`-th of them (a copy)
/// when there are more than [`MAX_SEARCH_POINTS`], `stride = ceil(n / MAX_SEARCH_POINTS)`.
pub(super) fn search_points<T: Copy>(points: &[T]) -> std::borrow::Cow<'_, [T]> {
    let stride = points.len().div_ceil(MAX_SEARCH_POINTS).max(1);
    if stride > 1 {
        std::borrow::Cow::Owned(points.iter().step_by(stride).copied().collect())
    } else {
        std::borrow::Cow::Borrowed(points)
    }
}

/// The best model of a RANSAC search and its score, with the search's counts: [`ransac`] before
/// its final refit on every point.
pub(super) struct Search<M> {
    model: M,
    score: Score,
    drawn: usize,
    scored: usize,
    point_tests: u64,
}

impl<M: Copy> Search<M> {
    /// How RANSAC ends: the best model refitted by least squares on its inliers, `support(model)`
    /// (indices into `points`, ascending), and the result with that refit's inliers.
    pub(super) fn finish<E: Estimator<Model = M>>(
        self,
        estimator: &E,
        points: &[Point3<f64>],
        support: impl Fn(&M) -> Vec<usize>,
    ) -> RansacResult<M> {
        let first = support(&self.model);
        let model = estimator.refit(points, &first).unwrap_or(self.model);
        let support = support(&model);
        RansacResult {
            model,
            rms: rms(estimator, points, &model, &support),
            inliers: support,
            cost: self.score.cost,
            hypotheses: self.drawn,
            scored: self.scored,
            point_tests: self.point_tests,
        }
    }
}

/// The search of [`ransac`] on `search` (all of it: at most [`MAX_SEARCH_POINTS`] points, see
/// [`search_points`]).
pub(super) fn search<E: Estimator>(
    estimator: &E,
    search: &[Point3<f64>],
    options: &RansacOptions,
) -> Result<Search<E::Model>> {
    let s = E::SAMPLE_SIZE;
    let n_search = search.len();
    let cloud = Cloud::new(search)?;
    estimator.check_cloud(search)?;
    let threshold = options.distance_threshold;

    let mut best: Option<(E::Model, Score)> = None;
    let mut required = options.max_iterations;
    let (mut drawn, mut scored, mut point_tests) = (0usize, 0usize, 0u64);
    let mut batch = 0u64;
    while drawn < required {
        if let Some(deadline) = &options.deadline {
            deadline.check(&format!("RANSAC ({} search)", E::NAME))?;
        }
        let len = BATCH.min(options.max_iterations - drawn);
        let samples = draw_batch(options.seed, batch, len, s, n_search);
        batch += 1;
        drawn += len;
        let models: Vec<E::Model> = samples
            .chunks_exact(s)
            .filter_map(|sample| estimator.minimal_model(search, sample))
            .collect();
        if models.is_empty() {
            continue;
        }
        let scores = score_models(estimator, &cloud, &models, threshold, false);
        scored += models.len();
        point_tests += (models.len() * n_search) as u64;
        // The batch's best: lowest cost, the earliest hypothesis on ties.
        let mut k_best = 0;
        for (k, sc) in scores.iter().enumerate() {
            if sc.cost < scores[k_best].cost {
                k_best = k;
            }
        }
        let candidate = scores[k_best];
        if best.as_ref().is_none_or(|(_, b)| candidate.cost < b.cost) {
            let improved = local_optimization(
                estimator,
                &cloud,
                models[k_best],
                candidate,
                options,
                &mut point_tests,
            );
            required = required_hypotheses(
                improved.1.inliers,
                n_search,
                s,
                options.confidence,
                options.max_iterations,
            );
            best = Some(improved);
        }
    }

    let Some((model, score)) = best else {
        return Err(Error::Degenerate(format!(
            "all {drawn} samples were degenerate: the points do not determine a {}",
            E::NAME
        )));
    };
    Ok(Search {
        model,
        score,
        drawn,
        scored,
        point_tests,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn required_hypotheses_matches_formula() {
        // w = 0.5, s = 3, p = 0.99: log(0.01) / log(1 - 0.125) = 34.5 -> 35.
        assert_eq!(required_hypotheses(50, 100, 3, 0.99, 10_000), 35);
        assert_eq!(required_hypotheses(100, 100, 3, 0.99, 10_000), 1);
        assert_eq!(required_hypotheses(0, 100, 3, 0.99, 10_000), 10_000);
        assert_eq!(required_hypotheses(1, 1_000_000, 3, 0.999, 500), 500);
    }
}
