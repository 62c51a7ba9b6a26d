//! Levenberg–Marquardt on a noisy three-plane alignment: accuracy against ground truth, the
//! covariance estimate, and determinism across thread counts.

mod common;

use lidarcal::geometry::rotation_angle;
use lidarcal::lm::{solve, LmOptions, Loss};
use lidarcal::residuals::PointToPlane;

fn errors(estimate: &nalgebra::Isometry3<f64>) -> (f64, f64) {
    let truth = common::true_pose();
    let r = rotation_angle(&(truth.rotation * estimate.rotation.inverse()).to_rotation_matrix());
    let t = (truth.translation.vector - estimate.translation.vector).norm();
    (r, t)
}

#[test]
fn noisy_corner_converges_near_truth() {
    let problem = PointToPlane::new(common::corner_groups(3000, 0.02, 11), Loss::Squared).unwrap();
    let solution = solve(&problem, &common::perturbed_start(), &LmOptions::default()).unwrap();
    let report = solution.report;
    assert!(report.converged(), "{report:?}");
    assert!(report.iterations < 30, "{} iterations", report.iterations);
    let (r_err, t_err) = errors(&solution.pose);
    // 9000 points with 2 cm noise: errors of a few thousandths at most.
    assert!(r_err < 1e-3, "rotation error {r_err} rad");
    assert!(t_err < 5e-3, "translation error {t_err} m");
    // Residual RMS recovers the simulated noise level.
    let sigma = (2.0 * report.final_cost / report.residual_count as f64).sqrt();
    assert!((sigma - 0.02).abs() < 1e-3, "estimated noise {sigma}");
    // The covariance is symmetric positive definite and its scale matches the actual error.
    let cov = report.covariance().expect("covariance");
    assert!((cov - cov.transpose()).amax() < 1e-12 * cov.amax());
    assert!(cov.cholesky().is_some());
    let rot_sd = (cov[(3, 3)] + cov[(4, 4)] + cov[(5, 5)]).sqrt();
    assert!(
        r_err < 6.0 * rot_sd,
        "error {r_err} vs predicted sd {rot_sd}"
    );
}

#[test]
fn robust_loss_resists_outliers() {
    let mut groups = common::corner_groups(2000, 0.01, 5);
    // 10% of the first plane's points replaced by clutter half a metre off the plane.
    for (i, p) in groups[0]
        .points
        .iter_mut()
        .enumerate()
        .filter(|(i, _)| i % 10 == 0)
    {
        p.x += 0.5 + (i % 7) as f64 * 0.1;
    }
    let start = common::perturbed_start();
    let plain = solve(
        &PointToPlane::new(groups.clone(), Loss::Squared).unwrap(),
        &start,
        &LmOptions::default(),
    )
    .unwrap();
    let robust = solve(
        &PointToPlane::new(groups, Loss::Cauchy { scale: 0.03 }).unwrap(),
        &start,
        &LmOptions::default(),
    )
    .unwrap();
    let (_, t_plain) = errors(&plain.pose);
    let (r_robust, t_robust) = errors(&robust.pose);
    assert!(
        t_robust < 3e-3 && r_robust < 1e-3,
        "robust {r_robust} {t_robust}"
    );
    assert!(
        t_plain > 5.0 * t_robust,
        "plain {t_plain} vs robust {t_robust}"
    );
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let problem = PointToPlane::new(
        common::corner_groups(6000, 0.02, 3),
        Loss::Huber { delta: 0.05 },
    )
    .unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| solve(&problem, &common::perturbed_start(), &LmOptions::default()).unwrap())
    };
    let one = run(1);
    let two = run(2);
    let four = run(4);
    assert_eq!(one.pose.to_homogeneous(), two.pose.to_homogeneous());
    assert_eq!(one.pose.to_homogeneous(), four.pose.to_homogeneous());
    assert_eq!(one.report, two.report);
}
