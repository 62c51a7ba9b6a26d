//! The targetless plane-matching method on simulated streets and the real road scenes.

mod common;

use lidarcal::calib::targetless::{calibrate_targetless, pose_error, TargetlessOptions};
use lidarcal::sim::scenes::{corridor_scene, street_scene, Side, StreetOptions};

#[test]
#[ignore]
fn explore_real() {
    let Some(dir) = common::require_sensors_calibration() else {
        return;
    };
    for scene in common::REAL_WORLD_SCENES {
        let base = dir.join("real_world").join(scene);
        let top = common::load_npy_xyz(&base.join("top.npy"));
        for side in ["left", "right"] {
            let truth = common::reference_extrinsic(&dir, &[scene, &format!("{side}_to_top")]);
            let tgt = common::load_npy_xyz(&base.join(format!("{side}.npy")));
            let t0 = std::time::Instant::now();
            let r = calibrate_targetless(&top, &tgt, &TargetlessOptions::default());
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            match r {
                Ok(r) => {
                    let (a, d) = pose_error(&truth, &r.reference_from_target);
                    let (a0, d0) = pose_error(&truth, &r.initial_reference_from_target);
                    println!(
                        "{scene} {side}: {:.3} deg {:.3} m (initial {:.2} deg {:.2} m) best {:.3} second {:.3} matched {} hyp {:?} triplet {} weak {:.4} {:?} thr {:?} planes {} {} {ms:.0} ms {:?}",
                        a.to_degrees(), d, a0.to_degrees(), d0, r.best_score, r.second_score,
                        r.planes_reference.len(), r.hypotheses, r.triplet, r.weakest_translation.1,
                        r.weakest_translation.0.as_slice(), r.distance_thresholds,
                        r.features[0].len(), r.features[1].len(), r.timings.stages
                    );
                }
                Err(e) => println!("{scene} {side}: {e} {ms:.0} ms"),
            }
        }
    }
}

#[test]
#[ignore]
fn explore_sim() {
    for seed in 0..4 {
        for side in [Side::Left, Side::Right] {
            let scene = street_scene(&StreetOptions {
                seed,
                side,
                ..StreetOptions::default()
            })
            .unwrap();
            let r = calibrate_targetless(
                &scene.reference.positions(),
                &scene.target.positions(),
                &TargetlessOptions::default(),
            );
            match r {
                Ok(r) => {
                    let (a, d) = pose_error(&scene.reference_from_target, &r.reference_from_target);
                    println!("street {seed} {side:?}: n={} {} {:.3} deg {:.3} m best {:.3} second {:.3} matched {} weak {:.4} {:?} {:?}", scene.reference.len(), scene.target.len(), a.to_degrees(), d, r.best_score, r.second_score, r.planes_reference.len(), r.weakest_translation.1, r.weakest_translation.0.as_slice(), r.timings.stages);
                }
                Err(e) => println!("street {seed} {side:?}: {e}"),
            }
        }
    }
    let scene = corridor_scene(0).unwrap();
    let r = calibrate_targetless(
        &scene.reference.positions(),
        &scene.target.positions(),
        &TargetlessOptions::default(),
    );
    println!(
        "corridor: {:?}",
        r.map(|r| (
            pose_error(&scene.reference_from_target, &r.reference_from_target),
            r.weakest_translation
        ))
    );
}

#[test]
#[ignore]
fn explore_planes() {
    let Some(dir) = common::require_sensors_calibration() else {
        return;
    };
    let scene = std::env::var("SCENE").unwrap_or(common::REAL_WORLD_SCENES[2].into());
    let base = dir.join("real_world").join(&scene);
    for side in ["top", "left", "right"] {
        let truth = if side == "top" {
            nalgebra::Isometry3::identity()
        } else {
            common::reference_extrinsic(&dir, &[&scene, &format!("{side}_to_top")])
        };
        let pts = common::load_npy_xyz(&base.join(format!("{side}.npy")));
        let (f, t) = lidarcal::calib::targetless::plane_features(
            &pts,
            &TargetlessOptions {
                max_planes: 14,
                ..TargetlessOptions::default()
            },
        )
        .unwrap();
        println!("{side} threshold {t:.3}");
        for p in f {
            let q = p.plane.transformed(&truth);
            let c = truth * p.centroid;
            println!("  n=[{:6.3} {:6.3} {:6.3}] d={:6.2} N={:5} c=[{:6.1} {:6.1} {:5.1}] ext={:.1}x{:.1}", q.normal.x, q.normal.y, q.normal.z, q.offset, p.voxels.len(), c.x, c.y, c.z, p.extent[0], p.extent[1]);
        }
    }
}
