//! The pole method on simulated scenes with ground truth.

use lidarcal::calib::poles::{calibrate_poles, AxisFit, PoleCalibration, PoleOptions, Vendor};
use lidarcal::sim::scenes::{poles_scene, PolesOptions, Scene};
use lidarcal::sim::{BeamModel, Preset, Scan};
use lidarcal::{Error, Result};
use nalgebra::Point3;

fn split(scan: &Scan) -> (Vec<Point3<f64>>, Vec<f64>) {
    (
        scan.positions(),
        scan.points.iter().map(|p| p.intensity).collect(),
    )
}

fn run(scene: &Scene, options: &PoleOptions) -> Result<PoleCalibration> {
    let (r, ri) = split(&scene.reference);
    let (t, ti) = split(&scene.target);
    calibrate_poles(&r, &ri, &t, &ti, options)
}

/// (rotation error rad, translation error m).
fn errors(scene: &Scene, result: &PoleCalibration) -> (f64, f64) {
    let e = result.reference_from_target.inverse() * scene.reference_from_target;
    (e.rotation.angle(), e.translation.vector.norm())
}

#[test]
fn explore() {
    let model = BeamModel::preset(Preset::Vlp16);
    for seed in 0..20u64 {
        let radius = 0.05 + 0.1 * (seed as f64 / 19.0);
        let scene = poles_scene(
            &model,
            &PolesOptions {
                seed,
                radius,
                max_tilt_deg: std::env::var("TILT")
                    .map(|v| v.parse().unwrap())
                    .unwrap_or(15.0),
                distractor: std::env::var("DISTRACTOR").is_ok(),
                ..PolesOptions::default()
            },
        )
        .unwrap();
        for fit in [AxisFit::Cylinder, AxisFit::Line] {
            let o = PoleOptions {
                vendor: Some(Vendor::Velodyne),
                axis_fit: fit,
                ..PoleOptions::default()
            };
            match run(&scene, &o) {
                Ok(r) => {
                    let (er, et) = errors(&scene, &r);
                    let scores: Vec<String> = r
                        .hypotheses
                        .iter()
                        .map(|h| {
                            format!(
                                "{:.1}({:.3},{:.1},{:.2},{:.2})",
                                h.score,
                                h.axis_rms,
                                h.ground_angle.unwrap_or(f64::NAN).to_degrees(),
                                h.ground_offset.unwrap_or(f64::NAN),
                                h.overlap
                            )
                        })
                        .collect();
                    println!(
                        "n {} {} {:?}",
                        scene.reference.len(),
                        scene.target.len(),
                        r.timings.stages
                    );
                    println!("seed {seed} r {radius:.3} {fit:?}: rot {:.4} trans {:.4} margin {:.2} ms {:.1} | {}", er, et, r.margin, r.timings.total(), scores.join(" "));
                }
                Err(e) => println!("seed {seed} {fit:?}: ERR {e}"),
            }
        }
    }
    let _ = Error::Io(String::new());
}

#[test]
fn look13() {
    let model = BeamModel::preset(Preset::Vlp16);
    let scene = poles_scene(
        &model,
        &PolesOptions {
            seed: 13,
            radius: 0.113,
            ..PolesOptions::default()
        },
    )
    .unwrap();
    for p in &scene.poles {
        println!("{:?} {:?}", p.axis.point, p.axis.direction);
    }
    let w = scene.world_from_reference;
    for p in &scene.poles {
        println!(
            "world {:?} top {:?}",
            w * p.axis.point,
            w * (p.axis.point + p.axis.direction.into_inner() * 3.0)
        );
    }
}
