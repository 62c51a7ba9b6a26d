//! Quick start: two simulated VLP-16s at a building corner, calibrated from the three planes
//! without an initial guess, and compared with the simulator's ground truth.
//!
//! Run with `cargo run --example quickstart` (needs the default feature `sim`).

use lidarcal::calib::planes::{calibrate_planes, PlanarOptions};
use lidarcal::sim::scenes::{corner_scene, CornerOptions};
use lidarcal::sim::{BeamModel, Preset};
use nalgebra::Vector3;

fn main() -> Result<(), lidarcal::Error> {
    // Two walls at 90 degrees and the ground, 4 clutter boxes; the target tilted and turned.
    let scene = corner_scene(&BeamModel::preset(Preset::Vlp16), &CornerOptions::default())?;
    let (reference, target) = (scene.reference.positions(), scene.target.positions());
    println!("{} + {} points", reference.len(), target.len());

    // A right-angled corner is a cube corner: a 120-degree turn about its diagonal maps the three
    // planes onto each other, so without a tie-break the method refuses rather than guess.
    if let Err(e) = calibrate_planes(&reference, &target, &PlanarOptions::default()) {
        println!("without up: {e}");
    }
    // `up`, the gravity direction in each sensor's frame, breaks the tie. Both sensors stand
    // roughly upright (tilts under 10 degrees), so it is +z in both.
    let options = PlanarOptions {
        up: Some((Vector3::z(), Vector3::z())),
        ..PlanarOptions::default()
    };
    let result = calibrate_planes(&reference, &target, &options)?;

    let (truth, estimate) = (scene.reference_from_target, result.reference_from_target);
    let rotation_error_deg = (truth.rotation * estimate.rotation.inverse())
        .angle()
        .to_degrees();
    let translation_error_m = (truth.translation.vector - estimate.translation.vector).norm();
    for (name, pose) in [("truth", &truth), ("estimate", &estimate)] {
        let (roll, pitch, yaw) = pose.rotation.euler_angles();
        let t = pose.translation.vector;
        println!(
            "{name:>8}: rpy deg [{:+.4}, {:+.4}, {:+.4}]  t m [{:+.4}, {:+.4}, {:+.4}]",
            roll.to_degrees(),
            pitch.to_degrees(),
            yaw.to_degrees(),
            t.x,
            t.y,
            t.z
        );
    }
    println!(
        "error: rotation {rotation_error_deg:.4} deg, translation {:.2} mm; check: {}",
        translation_error_m * 1e3,
        result.check.verdict
    );
    assert!(rotation_error_deg < 0.05 && translation_error_m < 0.005);
    Ok(())
}
