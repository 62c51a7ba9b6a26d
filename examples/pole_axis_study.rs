//! The pole-axis study: for a VLP-16 at 4, 6 and 10 m from a pole of radius 0.1, 0.2 and 0.3 m,
//! the offset between the pole's true axis and (a) the line fitted through its points, (b) the axis
//! of a fitted cylinder (radius known), (c) the same with the radius estimated. Prints a markdown
//! table of the mean and max over `TRIALS` seeds.
//!
//! `cargo run --release --example pole_axis_study`

use lidarcal::sim::study::pole_axis_trial;

const TRIALS: u64 = 20;

fn main() -> Result<(), lidarcal::Error> {
    println!(
        "| distance (m) | radius (m) | points | line: mean (m) | line: max (m) | cylinder: mean (m) | \
         cylinder: max (m) | cylinder, r free: mean (m) | r free: estimated r (m) |"
    );
    println!("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for distance in [4.0, 6.0, 10.0] {
        for radius in [0.1, 0.2, 0.3] {
            let trials = (0..TRIALS)
                .map(|seed| pole_axis_trial(distance, radius, seed))
                .collect::<Result<Vec<_>, _>>()?;
            let n = trials.len() as f64;
            let mean = |f: &dyn Fn(&lidarcal::sim::study::PoleAxisTrial) -> f64| {
                trials.iter().map(f).sum::<f64>() / n
            };
            let max = |f: &dyn Fn(&lidarcal::sim::study::PoleAxisTrial) -> f64| {
                trials.iter().map(f).fold(0.0, f64::max)
            };
            println!(
                "| {distance:.0} | {radius:.1} | {:.0} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.3} |",
                mean(&|t| t.points as f64),
                mean(&|t| t.line_error),
                max(&|t| t.line_error),
                mean(&|t| t.cylinder_error),
                max(&|t| t.cylinder_error),
                mean(&|t| t.cylinder_free_radius_error),
                mean(&|t| t.estimated_radius),
            );
        }
    }
    Ok(())
}
