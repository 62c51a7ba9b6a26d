//! Beam models of spinning multi-beam LiDARs: elevation tables, azimuth resolution, range limits and
//! a default range noise.
//!
//! The presets follow the manufacturers' published figures:
//!
//! | model | beams | elevations | columns / rev (10 Hz) | range | default noise (1 sigma) |
//! | --- | --- | --- | --- | --- | --- |
//! | Velodyne VLP-16 | 16 | -15..+15 deg, 2 deg steps | 1800 (0.2 deg) | 0.5–100 m | 0.015 m |
//! | Velodyne HDL-32E | 32 | -30.67..+10.67 deg, 4/3 deg steps | 2250 (0.16 deg) | 1–100 m | 0.010 m |
//! | Velodyne HDL-64E | 64 | upper block -8.33..+2 deg, lower block -24.33..-8.83 deg | 2000 (0.18 deg) | 0.9–120 m | 0.010 m |
//! | Ouster OS1-128 | 128 | -22.5..+22.5 deg, uniform | 2048 | 0.3–120 m | 0.015 m |
//!
//! The HDL-64E's real per-laser calibration table is not uniform; here each of its two 32-laser
//! blocks is spaced uniformly between the published end points (about 1/3 deg and 1/2 deg), which
//! is within a few hundredths of a degree of the nominal table and enough for simulation. The
//! default noise is a 1-sigma reading of the datasheets' "accuracy" figures.
//!
//! Ring indices count beams from the lowest elevation (ring 0) upward, in every model.

use crate::error::{Error, Result};

/// Largest number of beams a model may have (ring indices are stored as `u16`).
pub const MAX_BEAMS: usize = u16::MAX as usize;
/// Largest number of azimuth columns per revolution accepted (0.001 deg resolution).
pub const MAX_COLUMNS: usize = 360_000;
/// Largest range noise (metres, 1 sigma) accepted: anything above is not a LiDAR.
pub const MAX_RANGE_NOISE: f64 = 10.0;
/// A full turn in degrees: the horizontal field of view of a spinning LiDAR, the default.
pub const FULL_TURN_DEG: f64 = 360.0;
/// Slack (in azimuth steps) when counting the columns of a limited field of view, so that a field
/// that is a whole number of steps wide keeps its last column despite rounding.
const COLUMN_COUNT_SLACK: f64 = 1e-9;

/// The preset sensors. The default, the VLP-16, is the model the scenes and `lidarcal.sim` use
/// when none is named.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Preset {
    /// Velodyne VLP-16 (Puck).
    #[default]
    Vlp16,
    /// Velodyne HDL-32E.
    Hdl32e,
    /// Velodyne HDL-64E.
    Hdl64e,
    /// Ouster OS1-128.
    Os1_128,
}

impl Preset {
    /// All presets, in the order of the table above.
    pub const ALL: [Preset; 4] = [
        Preset::Vlp16,
        Preset::Hdl32e,
        Preset::Hdl64e,
        Preset::Os1_128,
    ];

    /// The short name used by the CLI and Python (`vlp16`, `hdl32`, `hdl64`, `os128`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Vlp16 => "vlp16",
            Preset::Hdl32e => "hdl32",
            Preset::Hdl64e => "hdl64",
            Preset::Os1_128 => "os128",
        }
    }

    /// The preset with short name `name` (case-insensitive; `hdl32e`, `hdl64e`, `os1-128` and
    /// `os1_128` are accepted too).
    pub fn from_name(name: &str) -> Result<Preset> {
        match name.to_ascii_lowercase().as_str() {
            "vlp16" | "vlp-16" => Ok(Preset::Vlp16),
            "hdl32" | "hdl32e" | "hdl-32e" => Ok(Preset::Hdl32e),
            "hdl64" | "hdl64e" | "hdl-64e" => Ok(Preset::Hdl64e),
            "os128" | "os1-128" | "os1_128" => Ok(Preset::Os1_128),
            other => Err(Error::InvalidInput(format!(
                "unknown LiDAR model {other:?}; expected one of vlp16, hdl32, hdl64, os128"
            ))),
        }
    }
}

/// The settings of a custom [`BeamModel`] besides its elevations, in the order
/// [`BeamModel::custom`] takes them. The default is a VLP-16's azimuth resolution and range limits
/// with 1 cm range noise: what `lidarcal.sim.BeamModel.custom` uses for a setting it is not given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeamSettings {
    /// Azimuth columns per revolution.
    pub columns: usize,
    /// Shortest range measured, metres.
    pub min_range: f64,
    /// Longest range measured, metres.
    pub max_range: f64,
    /// Range noise, metres (1 sigma, along the beam).
    pub range_noise: f64,
}

impl Default for BeamSettings {
    fn default() -> Self {
        BeamSettings {
            columns: 1800,
            min_range: 0.5,
            max_range: 100.0,
            range_noise: 0.01,
        }
    }
}

/// A spinning multi-beam LiDAR: one beam per elevation, fired at `columns` equally spaced azimuths
/// per revolution, starting at azimuth 0 (the sensor's +x axis) and turning counter-clockwise
/// about +z.
///
/// A model may have a limited horizontal field of view ([`BeamModel::with_horizontal_fov`]),
/// centred on +x: it then fires only the columns of the same azimuth grid step whose azimuths lie
/// in `[-fov/2, fov/2]`, starting at `-fov/2` (see [`BeamModel::first_azimuth`] and
/// [`BeamModel::swept_columns`]). The default field is the full turn.
#[derive(Debug, Clone, PartialEq)]
pub struct BeamModel {
    name: String,
    elevations: Vec<f64>,
    columns: usize,
    min_range: f64,
    max_range: f64,
    range_noise: f64,
    /// Horizontal field of view, radians, in `(0, 2 pi]`.
    horizontal_fov: f64,
}

fn uniform(first_deg: f64, last_deg: f64, count: usize) -> Vec<f64> {
    let step = (last_deg - first_deg) / (count.max(2) - 1) as f64;
    (0..count)
        .map(|i| (first_deg + step * i as f64).to_radians())
        .collect()
}

impl BeamModel {
    /// A preset model.
    pub fn preset(preset: Preset) -> BeamModel {
        let (elevations, columns, min_range, max_range, range_noise) = match preset {
            Preset::Vlp16 => (uniform(-15.0, 15.0, 16), 1800, 0.5, 100.0, 0.015),
            Preset::Hdl32e => (uniform(-30.67, 10.67, 32), 2250, 1.0, 100.0, 0.010),
            Preset::Hdl64e => {
                let mut e = uniform(-24.33, -8.83, 32);
                e.extend(uniform(-8.33, 2.0, 32));
                (e, 2000, 0.9, 120.0, 0.010)
            }
            Preset::Os1_128 => (uniform(-22.5, 22.5, 128), 2048, 0.3, 120.0, 0.015),
        };
        BeamModel {
            name: preset.name().to_string(),
            elevations,
            columns,
            min_range,
            max_range,
            range_noise,
            horizontal_fov: FULL_TURN_DEG.to_radians(),
        }
    }

    /// The preset with short name `name` (see [`Preset::from_name`]).
    pub fn from_name(name: &str) -> Result<BeamModel> {
        Ok(BeamModel::preset(Preset::from_name(name)?))
    }

    /// A custom model from beam elevations in **degrees** (any order; rings are numbered by
    /// ascending elevation), azimuth columns per revolution, range limits (metres) and range noise
    /// (metres, 1 sigma).
    pub fn custom(
        name: &str,
        elevations_deg: &[f64],
        columns: usize,
        min_range: f64,
        max_range: f64,
        range_noise: f64,
    ) -> Result<BeamModel> {
        if elevations_deg.is_empty() {
            return Err(Error::InvalidInput(
                "a beam model needs at least one elevation, got an empty list".into(),
            ));
        }
        if elevations_deg.len() > MAX_BEAMS {
            return Err(Error::InvalidInput(format!(
                "a beam model has at most {MAX_BEAMS} beams, got {}",
                elevations_deg.len()
            )));
        }
        crate::error::ensure_finite("elevations", elevations_deg)?;
        if let Some(e) = elevations_deg.iter().find(|e| e.abs() >= 90.0) {
            return Err(Error::InvalidInput(format!(
                "beam elevations must lie strictly between -90 and 90 degrees, got {e}"
            )));
        }
        if columns == 0 || columns > MAX_COLUMNS {
            return Err(Error::InvalidInput(format!(
                "azimuth columns per revolution must be in 1..={MAX_COLUMNS}, got {columns}"
            )));
        }
        if !(min_range.is_finite() && min_range >= 0.0) {
            return Err(Error::InvalidInput(format!(
                "min_range must be finite and >= 0, got {min_range}"
            )));
        }
        if !(max_range.is_finite() && max_range > min_range) {
            return Err(Error::InvalidInput(format!(
                "max_range must be finite and > min_range ({min_range}), got {max_range}"
            )));
        }
        check_noise(range_noise)?;
        let mut elevations: Vec<f64> = elevations_deg.iter().map(|e| e.to_radians()).collect();
        elevations.sort_by(f64::total_cmp);
        Ok(BeamModel {
            name: name.to_string(),
            elevations,
            columns,
            min_range,
            max_range,
            range_noise,
            horizontal_fov: FULL_TURN_DEG.to_radians(),
        })
    }

    /// The same model with a horizontal field of view of `degrees` in `(0, 360]`, centred on the
    /// sensor's +x axis (a forward-looking solid-state or masked unit). 360, the default, is the
    /// full turn and sweeps exactly as a model without a limit does.
    pub fn with_horizontal_fov(mut self, degrees: f64) -> Result<BeamModel> {
        if !(degrees.is_finite() && degrees > 0.0 && degrees <= FULL_TURN_DEG) {
            return Err(Error::InvalidInput(format!(
                "horizontal field of view must be in (0, {FULL_TURN_DEG}] degrees, got {degrees}"
            )));
        }
        self.horizontal_fov = degrees.to_radians();
        Ok(self)
    }

    /// The same model with another default range noise (metres, 1 sigma).
    pub fn with_range_noise(mut self, range_noise: f64) -> Result<BeamModel> {
        check_noise(range_noise)?;
        self.range_noise = range_noise;
        Ok(self)
    }

    /// The model's name (`vlp16`, ... or the custom name).
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Beam elevations in radians, ascending; index = ring.
    pub fn elevations(&self) -> &[f64] {
        &self.elevations
    }
    /// Number of beams (rings).
    pub fn beams(&self) -> usize {
        self.elevations.len()
    }
    /// Azimuth columns per revolution.
    pub fn columns(&self) -> usize {
        self.columns
    }
    /// Azimuth step in radians.
    pub fn azimuth_step(&self) -> f64 {
        std::f64::consts::TAU / self.columns as f64
    }
    /// Shortest range measured (metres); nearer surfaces give no return.
    pub fn min_range(&self) -> f64 {
        self.min_range
    }
    /// Longest range measured (metres).
    pub fn max_range(&self) -> f64 {
        self.max_range
    }
    /// Default range noise, metres (1 sigma, along the beam).
    pub fn range_noise(&self) -> f64 {
        self.range_noise
    }
    /// Horizontal field of view in radians, in `(0, 2 pi]`.
    pub fn horizontal_fov(&self) -> f64 {
        self.horizontal_fov
    }
    /// Whether the field of view is the full turn.
    pub fn is_full_turn(&self) -> bool {
        self.horizontal_fov >= std::f64::consts::TAU
    }
    /// Azimuth of the first column fired (radians): 0 for the full turn, `-fov/2` otherwise.
    pub fn first_azimuth(&self) -> f64 {
        if self.is_full_turn() {
            0.0
        } else {
            -0.5 * self.horizontal_fov
        }
    }
    /// Number of columns fired per revolution: [`columns`](Self::columns) for the full turn,
    /// otherwise those of the azimuth grid in `[-fov/2, fov/2]` counted from `-fov/2` (at least
    /// one, at most `columns`). Column `j` is fired at `first_azimuth() + j * azimuth_step()`.
    pub fn swept_columns(&self) -> usize {
        if self.is_full_turn() {
            return self.columns;
        }
        let steps = (self.horizontal_fov / self.azimuth_step() + COLUMN_COUNT_SLACK).floor();
        // `steps` is finite, non-negative and below `columns` here; the cast cannot truncate.
        (steps as usize + 1).min(self.columns)
    }
}

pub(crate) fn check_noise(range_noise: f64) -> Result<()> {
    if !(range_noise.is_finite() && (0.0..=MAX_RANGE_NOISE).contains(&range_noise)) {
        return Err(Error::InvalidInput(format!(
            "range noise must be in [0, {MAX_RANGE_NOISE}] metres, got {range_noise}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_match_published_tables() {
        let vlp = BeamModel::preset(Preset::Vlp16);
        assert_eq!(vlp.beams(), 16);
        assert!((vlp.elevations()[0].to_degrees() + 15.0).abs() < 1e-12);
        assert!((vlp.elevations()[1].to_degrees() + 13.0).abs() < 1e-12);
        assert!((vlp.elevations()[15].to_degrees() - 15.0).abs() < 1e-12);
        let hdl32 = BeamModel::preset(Preset::Hdl32e);
        assert_eq!(hdl32.beams(), 32);
        let step = (hdl32.elevations()[1] - hdl32.elevations()[0]).to_degrees();
        assert!((step - 4.0 / 3.0).abs() < 1e-3);
        let hdl64 = BeamModel::preset(Preset::Hdl64e);
        assert_eq!(hdl64.beams(), 64);
        assert!(hdl64.elevations().windows(2).all(|w| w[0] < w[1]));
        assert!((hdl64.elevations()[63].to_degrees() - 2.0).abs() < 1e-12);
        let os = BeamModel::preset(Preset::Os1_128);
        assert_eq!((os.beams(), os.columns()), (128, 2048));
        for p in Preset::ALL {
            assert_eq!(Preset::from_name(p.name()).unwrap(), p);
        }
    }

    #[test]
    fn custom_model_is_validated() {
        let m = BeamModel::custom("two", &[5.0, -5.0], 360, 0.1, 50.0, 0.0).unwrap();
        assert!(m.elevations()[0] < 0.0, "rings sorted by elevation");
        assert!(BeamModel::custom("x", &[], 360, 0.1, 50.0, 0.0).is_err());
        assert!(BeamModel::custom("x", &[f64::NAN], 360, 0.1, 50.0, 0.0).is_err());
        assert!(BeamModel::custom("x", &[90.0], 360, 0.1, 50.0, 0.0).is_err());
        assert!(BeamModel::custom("x", &[0.0], 0, 0.1, 50.0, 0.0).is_err());
        assert!(BeamModel::custom("x", &[0.0], 360, 5.0, 1.0, 0.0).is_err());
        assert!(BeamModel::custom("x", &[0.0], 360, 0.1, 50.0, -1.0).is_err());
        assert!(Preset::from_name("lux").is_err());
    }

    #[test]
    fn horizontal_field_of_view() {
        let full = BeamModel::preset(Preset::Vlp16);
        assert!(full.is_full_turn());
        assert_eq!((full.first_azimuth(), full.swept_columns()), (0.0, 1800));
        assert_eq!(full.clone().with_horizontal_fov(360.0).unwrap(), full);
        let fov = full.clone().with_horizontal_fov(120.0).unwrap();
        assert!(!fov.is_full_turn());
        // -60 to +60 degrees inclusive in 0.2 degree steps.
        assert_eq!(fov.swept_columns(), 601);
        assert!((fov.first_azimuth().to_degrees() + 60.0).abs() < 1e-12);
        let narrow = full.clone().with_horizontal_fov(0.1).unwrap();
        assert_eq!(narrow.swept_columns(), 1);
        for bad in [0.0, -10.0, 360.5, f64::NAN, f64::INFINITY] {
            assert!(full.clone().with_horizontal_fov(bad).is_err(), "{bad}");
        }
    }
}
