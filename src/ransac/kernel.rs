//! The MSAC scoring kernel shared by the estimators.
//!
//! Up to [`GROUP`] models are scored in one pass over a structure-of-arrays cloud, each point
//! tested against every model with the estimator's squared-distance function. Accumulators are
//! `f32` lanes (8 per model, SIMD-friendly), flushed to `f64` every 1024 points to
//! bound their rounding. The inlier count is a compile-time option: counting costs registers in
//! the hot loop and the search needs only the cost.
//!
//! On x86-64 the kernel is also compiled for AVX-512F and for AVX2, and the widest the CPU has is
//! picked at run time. FMA is deliberately not enabled: every lane does the same operations in the
//! same order as the baseline build, so results are bit-identical on machines with and without
//! either.

use super::consensus::{Score, GROUP};

/// Points per lane-accumulator block.
const BLOCK: usize = 1024;
/// Lanes of the accumulators.
const LANES: usize = 8;

/// MSAC scores of up to [`GROUP`] `models` over the cloud `(x, y, z)`; `out[k]` receives the
/// score of `models[k]` (with its inlier count when `count_inliers`). `d2(model, x, y, z)` is
/// the squared distance of a point to a model.
#[allow(clippy::too_many_arguments)]
pub fn score<M, F>(
    count_inliers: bool,
    x: &[f32],
    y: &[f32],
    z: &[f32],
    models: &[M],
    threshold: f32,
    out: &mut [Score],
    d2: F,
) where
    M: Copy + Default,
    F: Fn(&M, f32, f32, f32) -> f32 + Copy,
{
    let job = Job {
        count_inliers,
        x,
        y,
        z,
        models,
        threshold,
    };
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU supports AVX-512F, checked just above.
        unsafe { score_avx512(&job, out, d2) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { score_avx2(&job, out, d2) };
        return;
    }
    score_either(&job, out, d2)
}

/// What [`score`] scores: the cloud, the models and the threshold.
struct Job<'a, M> {
    count_inliers: bool,
    x: &'a [f32],
    y: &'a [f32],
    z: &'a [f32],
    models: &'a [M],
    threshold: f32,
}

/// A build of [`score`] with one x86-64 target feature enabled (see the module docs): `name`,
/// compiled for `feature`; call it only where the CPU has that feature.
macro_rules! score_with_feature {
    ($name:ident, $feature:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        unsafe fn $name<M, F>(job: &Job<'_, M>, out: &mut [Score], d2: F)
        where
            M: Copy + Default,
            F: Fn(&M, f32, f32, f32) -> f32 + Copy,
        {
            score_either(job, out, d2)
        }
    };
}

score_with_feature!(score_avx512, "avx512f");
score_with_feature!(score_avx2, "avx2");

/// [`score_impl`] with or without the inlier count, inlined into each build of [`score`].
#[inline(always)]
fn score_either<M, F>(job: &Job<'_, M>, out: &mut [Score], d2: F)
where
    M: Copy + Default,
    F: Fn(&M, f32, f32, f32) -> f32 + Copy,
{
    if job.count_inliers {
        score_impl::<M, F, true>(job, out, d2)
    } else {
        score_impl::<M, F, false>(job, out, d2)
    }
}

#[inline(always)]
fn score_impl<M, F, const COUNT: bool>(job: &Job<'_, M>, out: &mut [Score], d2: F)
where
    M: Copy + Default,
    F: Fn(&M, f32, f32, f32) -> f32 + Copy,
{
    let Job {
        x,
        y,
        z,
        models,
        threshold,
        ..
    } = *job;
    let count = models.len().min(GROUP).min(out.len());
    let mut group = [M::default(); GROUP];
    group[..count].copy_from_slice(&models[..count]);
    let t2 = threshold * threshold;
    let mut total_cost = [0f64; GROUP];
    let mut total_inliers = [0usize; GROUP];
    let n = x.len().min(y.len()).min(z.len());
    for start in (0..n).step_by(BLOCK) {
        let end = (start + BLOCK).min(n);
        let (xb, yb, zb) = (&x[start..end], &y[start..end], &z[start..end]);
        let mut cost = [[0f32; LANES]; GROUP];
        let mut hits = [[0u32; LANES]; GROUP];
        let mut xc = xb.chunks_exact(LANES);
        let mut yc = yb.chunks_exact(LANES);
        let mut zc = zb.chunks_exact(LANES);
        for ((xs, ys), zs) in (&mut xc).zip(&mut yc).zip(&mut zc) {
            for k in 0..GROUP {
                for l in 0..LANES {
                    let d = d2(&group[k], xs[l], ys[l], zs[l]);
                    let inside = d < t2;
                    cost[k][l] += if inside { d } else { t2 };
                    if COUNT {
                        hits[k][l] += inside as u32;
                    }
                }
            }
        }
        for ((xs, ys), zs) in xc
            .remainder()
            .iter()
            .zip(yc.remainder())
            .zip(zc.remainder())
        {
            for k in 0..GROUP {
                let d = d2(&group[k], *xs, *ys, *zs);
                let inside = d < t2;
                cost[k][0] += if inside { d } else { t2 };
                if COUNT {
                    hits[k][0] += inside as u32;
                }
            }
        }
        for k in 0..GROUP {
            total_cost[k] += cost[k].iter().map(|&c| f64::from(c)).sum::<f64>();
            total_inliers[k] += hits[k].iter().map(|&h| h as usize).sum::<usize>();
        }
    }
    for k in 0..count {
        out[k] = Score {
            cost: total_cost[k],
            inliers: total_inliers[k],
        };
    }
}
