//! Shapes a simulated beam can hit, and ray–shape intersection.
//!
//! Every shape is given in the world frame. [`Shape::intersect`] returns the nearest hit with a
//! ray parameter `t > 0` (the ray direction is a unit vector, so `t` is the range) and the
//! intensity range of the surface that was hit.

use nalgebra::{Isometry3, Point3, Unit, Vector3};

use crate::error::{ensure_finite, Error, Result};

/// Largest `|u . v| / (|u| |v|)` accepted between the two edges of a [`Rectangle`].
pub const EDGE_ORTHOGONALITY_TOLERANCE: f64 = 1e-6;
/// Rays closer to parallel with a surface than this (|cos| of the incidence angle) do not hit it.
const GRAZING: f64 = 1e-12;

/// The range of intensities (0–255, Velodyne's calibrated reflectivity scale) a surface returns; a
/// hit draws one uniformly from `[min, max]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntensityRange {
    /// Lowest intensity.
    pub min: f64,
    /// Highest intensity.
    pub max: f64,
}

impl IntensityRange {
    /// Diffuse building material (concrete, plaster).
    pub const WALL: IntensityRange = IntensityRange {
        min: 20.0,
        max: 70.0,
    };
    /// Asphalt or grass.
    pub const GROUND: IntensityRange = IntensityRange {
        min: 5.0,
        max: 40.0,
    };
    /// Painted metal or plastic clutter.
    pub const CLUTTER: IntensityRange = IntensityRange {
        min: 10.0,
        max: 90.0,
    };
    /// Painted poles and posts (outside a taped band).
    pub const POLE: IntensityRange = IntensityRange {
        min: 30.0,
        max: 80.0,
    };
    /// Retro-reflective tape or sign sheeting: above Velodyne's 230 threshold.
    pub const RETROREFLECTIVE: IntensityRange = IntensityRange {
        min: 235.0,
        max: 255.0,
    };

    /// A validated range: finite, `0 <= min <= max`.
    pub fn new(min: f64, max: f64) -> Result<Self> {
        if !(min.is_finite() && max.is_finite() && min >= 0.0 && min <= max) {
            return Err(Error::InvalidInput(format!(
                "intensity range must satisfy 0 <= min <= max (finite), got [{min}, {max}]"
            )));
        }
        Ok(IntensityRange { min, max })
    }

    /// The intensity at `u` in `[0, 1)`.
    pub fn at(&self, u: f64) -> f64 {
        self.min + (self.max - self.min) * u
    }
}

/// A finite rectangle `corner + s * edge_u + t * edge_v`, `s, t` in `[0, 1]` (a wall, the ground).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rectangle {
    corner: Point3<f64>,
    edge_u: Vector3<f64>,
    edge_v: Vector3<f64>,
    normal: Unit<Vector3<f64>>,
}

impl Rectangle {
    /// A rectangle from one corner and its two (orthogonal, non-zero) edge vectors.
    pub fn new(corner: Point3<f64>, edge_u: Vector3<f64>, edge_v: Vector3<f64>) -> Result<Self> {
        ensure_finite(
            "rectangle",
            corner
                .coords
                .iter()
                .chain(edge_u.iter())
                .chain(edge_v.iter()),
        )?;
        let (lu, lv) = (edge_u.norm(), edge_v.norm());
        if lu <= 0.0 || lv <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "rectangle edges must be non-zero, got lengths {lu} and {lv}"
            )));
        }
        let cos = edge_u.dot(&edge_v) / (lu * lv);
        if cos.abs() > EDGE_ORTHOGONALITY_TOLERANCE {
            return Err(Error::InvalidInput(format!(
                "rectangle edges must be orthogonal, got cos(angle) = {cos:.3e}"
            )));
        }
        Ok(Rectangle {
            corner,
            edge_u,
            edge_v,
            normal: Unit::new_normalize(edge_u.cross(&edge_v)),
        })
    }

    /// A rectangle centred at `center`, spanning `width` along `u_axis` and `height` along `v_axis`.
    pub fn centered(
        center: Point3<f64>,
        u_axis: Vector3<f64>,
        v_axis: Vector3<f64>,
        width: f64,
        height: f64,
    ) -> Result<Self> {
        ensure_finite("rectangle size", [width, height].iter())?;
        let (lu, lv) = (u_axis.norm(), v_axis.norm());
        if lu <= 0.0 || lv <= 0.0 || width <= 0.0 || height <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "rectangle axes and sizes must be non-zero and positive, got |u| = {lu}, |v| = {lv}, \
                 width = {width}, height = {height}"
            )));
        }
        let eu = u_axis * (width / lu);
        let ev = v_axis * (height / lv);
        Rectangle::new(center - eu * 0.5 - ev * 0.5, eu, ev)
    }

    /// The corner the edges start from.
    pub fn corner(&self) -> Point3<f64> {
        self.corner
    }
    /// First edge.
    pub fn edge_u(&self) -> Vector3<f64> {
        self.edge_u
    }
    /// Second edge.
    pub fn edge_v(&self) -> Vector3<f64> {
        self.edge_v
    }
    /// Unit normal `edge_u x edge_v` (normalised).
    pub fn normal(&self) -> Unit<Vector3<f64>> {
        self.normal
    }
    /// The infinite plane containing the rectangle.
    pub fn plane(&self) -> crate::geometry::Plane {
        crate::geometry::Plane {
            normal: self.normal,
            offset: -self.normal.dot(&self.corner.coords),
        }
    }

    fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<f64> {
        let denom = self.normal.dot(dir);
        if denom.abs() < GRAZING {
            return None;
        }
        let t = self.normal.dot(&(self.corner - origin)) / denom;
        if t <= 0.0 {
            return None;
        }
        let d = origin + dir * t - self.corner;
        let s = d.dot(&self.edge_u) / self.edge_u.norm_squared();
        let r = d.dot(&self.edge_v) / self.edge_v.norm_squared();
        ((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&r)).then_some(t)
    }
}

/// A box (clutter: cars, bins, crates) given by its pose `world_from_box` and half extents along the
/// box's own axes; the box frame's origin is its centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cuboid {
    world_from_box: Isometry3<f64>,
    half_extents: Vector3<f64>,
}

impl Cuboid {
    /// A box of full `size` (all positive) at `world_from_box`.
    pub fn new(world_from_box: Isometry3<f64>, size: Vector3<f64>) -> Result<Self> {
        ensure_finite("box size", size.iter())?;
        ensure_finite(
            "box pose",
            world_from_box
                .translation
                .vector
                .iter()
                .chain(world_from_box.rotation.coords.iter()),
        )?;
        if size.iter().any(|s| *s <= 0.0) {
            return Err(Error::InvalidInput(format!(
                "box sizes must be positive, got [{}, {}, {}]",
                size.x, size.y, size.z
            )));
        }
        Ok(Cuboid {
            world_from_box,
            half_extents: size * 0.5,
        })
    }
    /// The box pose (its centre and axes).
    pub fn world_from_box(&self) -> Isometry3<f64> {
        self.world_from_box
    }
    /// Half of the box's size along each of its axes.
    pub fn half_extents(&self) -> Vector3<f64> {
        self.half_extents
    }
    /// Whether `p` (world frame) is inside or on the box, with a tolerance `eps`.
    pub fn contains(&self, p: &Point3<f64>, eps: f64) -> bool {
        let q = self.world_from_box.inverse_transform_point(p);
        (0..3).all(|i| q[i].abs() <= self.half_extents[i] + eps)
    }

    fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<f64> {
        // Slab method in the box frame.
        let o = self.world_from_box.inverse_transform_point(origin);
        let d = self.world_from_box.inverse_transform_vector(dir);
        let (mut t_near, mut t_far) = (f64::NEG_INFINITY, f64::INFINITY);
        for i in 0..3 {
            let h = self.half_extents[i];
            if d[i].abs() < GRAZING {
                if o[i].abs() > h {
                    return None;
                }
                continue;
            }
            let (a, b) = ((-h - o[i]) / d[i], (h - o[i]) / d[i]);
            t_near = t_near.max(a.min(b));
            t_far = t_far.min(a.max(b));
        }
        if t_near > t_far || t_far <= 0.0 {
            return None;
        }
        // From inside the box the exit face is what the beam sees.
        Some(if t_near > 0.0 { t_near } else { t_far })
    }
}

/// A band of the cylinder's surface, `start..end` metres along the axis from the base, wrapped in
/// retro-reflective tape (or painted): it returns its own intensity range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// Start of the band along the axis, metres from the base.
    pub start: f64,
    /// End of the band along the axis, metres from the base.
    pub end: f64,
    /// Intensities the band returns.
    pub intensity: IntensityRange,
}

/// A finite solid cylinder (a pole): base centre, unit axis direction, length and radius; the
/// lateral surface and both end caps are hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    base: Point3<f64>,
    axis: Unit<Vector3<f64>>,
    length: f64,
    radius: f64,
    band: Option<Band>,
}

impl Cylinder {
    /// A cylinder from its base centre, axis direction (normalised here), length and radius.
    pub fn new(base: Point3<f64>, axis: Vector3<f64>, length: f64, radius: f64) -> Result<Self> {
        let line = crate::geometry::Line::new(base, axis)?;
        if !(length.is_finite() && length > 0.0) {
            return Err(Error::InvalidInput(format!(
                "cylinder length must be positive and finite, got {length}"
            )));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(Error::InvalidInput(format!(
                "cylinder radius must be positive and finite, got {radius}"
            )));
        }
        Ok(Cylinder {
            base,
            axis: line.direction,
            length,
            radius,
            band: None,
        })
    }

    /// The same cylinder with a band of its own intensity, `start..end` metres from the base.
    pub fn with_band(mut self, start: f64, end: f64, intensity: IntensityRange) -> Result<Self> {
        if !(start.is_finite() && end.is_finite() && 0.0 <= start && start < end) {
            return Err(Error::InvalidInput(format!(
                "band must satisfy 0 <= start < end (finite), got [{start}, {end}]"
            )));
        }
        let intensity = IntensityRange::new(intensity.min, intensity.max)?;
        self.band = Some(Band {
            start,
            end,
            intensity,
        });
        Ok(self)
    }

    /// Centre of the base cap.
    pub fn base(&self) -> Point3<f64> {
        self.base
    }
    /// Unit axis direction, from the base to the top.
    pub fn axis_direction(&self) -> Unit<Vector3<f64>> {
        self.axis
    }
    /// The axis as a line through the base centre.
    pub fn axis(&self) -> crate::geometry::Line {
        crate::geometry::Line {
            point: self.base,
            direction: self.axis,
        }
    }
    /// Length along the axis.
    pub fn length(&self) -> f64 {
        self.length
    }
    /// Radius.
    pub fn radius(&self) -> f64 {
        self.radius
    }
    /// The band, if any.
    pub fn band(&self) -> Option<Band> {
        self.band
    }

    /// Nearest hit and its axial coordinate (metres from the base).
    fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<(f64, f64)> {
        let a = self.axis.into_inner();
        let w = origin - self.base;
        let (wa, da) = (w.dot(&a), dir.dot(&a));
        let wp = w - a * wa;
        let dp = dir - a * da;
        let mut best: Option<(f64, f64)> = None;
        let mut consider = |t: f64, h: f64| {
            if t > 0.0 && best.is_none_or(|(b, _)| t < b) {
                best = Some((t, h));
            }
        };
        // Lateral surface: |wp + t dp|^2 = r^2.
        let qa = dp.norm_squared();
        if qa > GRAZING {
            let qb = wp.dot(&dp);
            let qc = wp.norm_squared() - self.radius * self.radius;
            let disc = qb * qb - qa * qc;
            if disc >= 0.0 {
                let sq = disc.sqrt();
                for t in [(-qb - sq) / qa, (-qb + sq) / qa] {
                    let h = wa + t * da;
                    if (0.0..=self.length).contains(&h) {
                        consider(t, h);
                    }
                }
            }
        }
        // End caps.
        if da.abs() > GRAZING {
            for h in [0.0, self.length] {
                let t = (h - wa) / da;
                if (wp + dp * t).norm_squared() <= self.radius * self.radius {
                    consider(t, h);
                }
            }
        }
        best
    }
}

/// The geometry of a [`Shape`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Geometry {
    /// A finite rectangle.
    Rectangle(Rectangle),
    /// A box.
    Cuboid(Cuboid),
    /// A finite cylinder.
    Cylinder(Cylinder),
}

/// A shape in the world: geometry and the intensity range its surface returns (a cylinder's band
/// overrides it inside the band).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shape {
    /// The geometry.
    pub geometry: Geometry,
    /// Intensities returned by the surface.
    pub intensity: IntensityRange,
}

/// A ray–shape intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter: the range for a unit direction.
    pub t: f64,
    /// Intensities of the surface at the hit.
    pub intensity: IntensityRange,
}

impl Shape {
    /// A rectangle with the given intensities.
    pub fn rectangle(rectangle: Rectangle, intensity: IntensityRange) -> Shape {
        Shape {
            geometry: Geometry::Rectangle(rectangle),
            intensity,
        }
    }
    /// A box with the given intensities.
    pub fn cuboid(cuboid: Cuboid, intensity: IntensityRange) -> Shape {
        Shape {
            geometry: Geometry::Cuboid(cuboid),
            intensity,
        }
    }
    /// A cylinder with the given intensities outside its band.
    pub fn cylinder(cylinder: Cylinder, intensity: IntensityRange) -> Shape {
        Shape {
            geometry: Geometry::Cylinder(cylinder),
            intensity,
        }
    }

    /// A sphere containing the shape: `(centre, radius)` (for culling shapes out of a sensor's
    /// range before scanning).
    pub fn bounding_sphere(&self) -> (Point3<f64>, f64) {
        match &self.geometry {
            Geometry::Rectangle(r) => {
                let half_diagonal = (r.edge_u + r.edge_v) * 0.5;
                (r.corner + half_diagonal, half_diagonal.norm())
            }
            Geometry::Cuboid(b) => (
                Point3::from(b.world_from_box.translation.vector),
                b.half_extents.norm(),
            ),
            Geometry::Cylinder(c) => {
                let half = 0.5 * c.length;
                (
                    c.base + c.axis.into_inner() * half,
                    (half * half + c.radius * c.radius).sqrt(),
                )
            }
        }
    }

    /// The nearest intersection of the ray `origin + t dir` (`dir` a unit vector) with `t > 0`.
    pub fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<Hit> {
        match &self.geometry {
            Geometry::Rectangle(r) => r.intersect(origin, dir).map(|t| Hit {
                t,
                intensity: self.intensity,
            }),
            Geometry::Cuboid(b) => b.intersect(origin, dir).map(|t| Hit {
                t,
                intensity: self.intensity,
            }),
            Geometry::Cylinder(c) => c.intersect(origin, dir).map(|(t, h)| {
                let intensity = match c.band {
                    Some(band) if (band.start..=band.end).contains(&h) => band.intensity,
                    _ => self.intensity,
                };
                Hit { t, intensity }
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_hits_inside_only() {
        let r = Rectangle::new(
            Point3::new(-1.0, -1.0, 0.0),
            Vector3::new(2.0, 0.0, 0.0),
            Vector3::new(0.0, 2.0, 0.0),
        )
        .unwrap();
        let o = Point3::new(0.5, 0.5, 3.0);
        assert!((r.intersect(&o, &-Vector3::z()).unwrap() - 3.0).abs() < 1e-12);
        assert!(r.intersect(&o, &Vector3::z()).is_none());
        assert!(r
            .intersect(&Point3::new(5.0, 0.0, 3.0), &-Vector3::z())
            .is_none());
        assert!(Rectangle::new(o, Vector3::x(), Vector3::new(1.0, 1.0, 0.0)).is_err());
        assert!(Rectangle::new(o, Vector3::zeros(), Vector3::y()).is_err());
    }

    #[test]
    fn cuboid_hits_near_face() {
        let b = Cuboid::new(
            Isometry3::translation(5.0, 0.0, 0.0),
            Vector3::new(2.0, 2.0, 2.0),
        )
        .unwrap();
        let t = b.intersect(&Point3::origin(), &Vector3::x()).unwrap();
        assert!((t - 4.0).abs() < 1e-12);
        assert!(b.intersect(&Point3::origin(), &Vector3::y()).is_none());
        assert!(b.intersect(&Point3::origin(), &-Vector3::x()).is_none());
        let inside = b
            .intersect(&Point3::new(5.0, 0.0, 0.0), &Vector3::x())
            .unwrap();
        assert!((inside - 1.0).abs() < 1e-12);
        assert!(Cuboid::new(Isometry3::identity(), Vector3::new(1.0, 0.0, 1.0)).is_err());
    }

    #[test]
    fn bounding_spheres_contain_the_shapes() {
        let r = Rectangle::new(
            Point3::new(1.0, 2.0, 0.0),
            Vector3::x() * 4.0,
            Vector3::z() * 3.0,
        )
        .unwrap();
        let (c, radius) = Shape::rectangle(r, IntensityRange::WALL).bounding_sphere();
        assert!((c - Point3::new(3.0, 2.0, 1.5)).norm() < 1e-12 && (radius - 2.5).abs() < 1e-12);
        let b = Cuboid::new(
            Isometry3::translation(5.0, 0.0, 1.0),
            Vector3::new(2.0, 2.0, 2.0),
        )
        .unwrap();
        let (c, radius) = Shape::cuboid(b, IntensityRange::CLUTTER).bounding_sphere();
        assert!((c - Point3::new(5.0, 0.0, 1.0)).norm() < 1e-12);
        assert!((radius - 3f64.sqrt()).abs() < 1e-12);
        let y = Cylinder::new(Point3::new(0.0, 0.0, 1.0), Vector3::z(), 6.0, 4.0).unwrap();
        let (c, radius) = Shape::cylinder(y, IntensityRange::POLE).bounding_sphere();
        assert!((c - Point3::new(0.0, 0.0, 4.0)).norm() < 1e-12 && (radius - 5.0).abs() < 1e-12);
    }

    #[test]
    fn cylinder_lateral_caps_and_band() {
        let c = Cylinder::new(Point3::new(4.0, 0.0, 0.0), Vector3::z(), 2.0, 0.5)
            .unwrap()
            .with_band(0.5, 1.5, IntensityRange::RETROREFLECTIVE)
            .unwrap();
        let shape = Shape::cylinder(c, IntensityRange::WALL);
        let hit = shape
            .intersect(&Point3::new(0.0, 0.0, 1.0), &Vector3::x())
            .unwrap();
        assert!((hit.t - 3.5).abs() < 1e-12);
        assert_eq!(hit.intensity, IntensityRange::RETROREFLECTIVE);
        let low = shape
            .intersect(&Point3::new(0.0, 0.0, 0.2), &Vector3::x())
            .unwrap();
        assert_eq!(low.intensity, IntensityRange::WALL);
        // From above: the top cap at z = 2.
        let top = shape
            .intersect(&Point3::new(4.1, 0.0, 5.0), &-Vector3::z())
            .unwrap();
        assert!((top.t - 3.0).abs() < 1e-12);
        assert!(shape
            .intersect(&Point3::new(0.0, 0.0, 3.0), &Vector3::x())
            .is_none());
        assert!(Cylinder::new(Point3::origin(), Vector3::z(), 1.0, -0.1).is_err());
        assert!(Cylinder::new(Point3::origin(), Vector3::zeros(), 1.0, 0.1).is_err());
        assert!(c.with_band(1.0, 0.5, IntensityRange::WALL).is_err());
        assert!(IntensityRange::new(10.0, 5.0).is_err());
    }
}
