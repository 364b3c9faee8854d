//! The person's points of one scan as a square image: the classifier's input (see
//! `docs/model_contract.md`).
//!
//! Pixel layout: `image[[row, col]]` covers map x in `[x0 + col * res, x0 + (col + 1) * res)`
//! and map y in `[y0 + row * res, y0 + (row + 1) * res)`, where `(x0, y0)` is the image's
//! centre minus half its side. Row 0 is the lowest y (no flip: the model does not care, the
//! dataset writer and the runtime only have to agree, which they do by sharing this code).
//!
//! Rendering runs per scan (twice with room-fixed framing and staggered states), so it never
//! allocates: it writes into a caller-owned array and only visits the pixels within a mark's
//! reach of each point. Non-finite points are skipped; points outside the image are not
//! counted, but their marks (circles, ellipses) are drawn where they reach into it.

use std::fmt;
use std::str::FromStr;

use glam::DVec2;
use ndarray::{Array2, ArrayViewMut2};
use serde::{Deserialize, Serialize};

/// What is drawn per point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RepresentationKind {
    /// 1 in the cell a point falls into (the paper's best variant).
    BooleanGrid,
    /// A filled disc of radius `mark_radius_m` around each point.
    Circles,
    /// A filled ellipse around each point, its long axis along the beam from the sensor (the
    /// range error is larger than the angle error).
    Ellipses,
}

/// Where the image is centred in the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Framing {
    /// Fixed in the map around the person's first visible position of the window (as the
    /// paper): movement through the room shows in the image.
    RoomFixed,
    /// Centred on the person's position at each scan: posture only, movement removed.
    PersonCentred,
}

/// Everything needed to turn points into an image. Stored in the model's metadata, so a
/// model file says how its input is made.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RepresentationSpec {
    pub kind: RepresentationKind,
    pub framing: Framing,
    /// Side of the square image in pixels.
    pub size: usize,
    /// Metres per pixel.
    pub resolution_m: f64,
    /// Radius of a circle mark (`circles`), metres.
    #[serde(default = "default_mark_radius")]
    pub mark_radius_m: f64,
    /// Semi-axes of an ellipse mark (`ellipses`), metres: along the beam, across it.
    #[serde(default = "default_ellipse_axes")]
    pub ellipse_axes_m: [f64; 2],
}

fn default_mark_radius() -> f64 {
    RepresentationSpec::DEFAULT_MARK_RADIUS_M
}

fn default_ellipse_axes() -> [f64; 2] {
    RepresentationSpec::DEFAULT_ELLIPSE_AXES_M
}

/// The largest image side (pixels), and the farthest a mark may reach from its point: a
/// mark reaching farther than any image is meaningless, and bounding it keeps the marks'
/// squared distances finite.
pub const MAX_SIZE: usize = 1024;

/// Why a representation spec cannot be used; each names the setting (the metadata key
/// without its `lidar_har.` prefix).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    #[error("size = {0}: the image side must be 1..={MAX_SIZE} pixels")]
    Size(usize),
    #[error("resolution_m = {0}: must be finite and positive, with finite pixels per metre")]
    Resolution(f64),
    #[error(
        "resolution_m = {resolution_m} with size = {size}: the image side (size x resolution_m) \
         must be finite"
    )]
    Extent { size: usize, resolution_m: f64 },
    #[error("{key} = {value}: must be finite and non-negative (metres)")]
    MarkSize { key: &'static str, value: f64 },
    #[error(
        "{key} = {value} with resolution_m = {resolution_m}: a mark may reach at most \
         {MAX_SIZE} pixels"
    )]
    MarkReach {
        key: &'static str,
        value: f64,
        resolution_m: f64,
    },
    #[error("unknown {what} '{value}' (expected one of: {expected})")]
    UnknownName {
        what: &'static str,
        value: String,
        expected: &'static str,
    },
}

impl RepresentationSpec {
    pub const DEFAULT_MARK_RADIUS_M: f64 = 0.05;
    pub const DEFAULT_ELLIPSE_AXES_M: [f64; 2] = [0.08, 0.03];

    pub fn new(kind: RepresentationKind, framing: Framing, size: usize, resolution_m: f64) -> Self {
        Self {
            kind,
            framing,
            size,
            resolution_m,
            mark_radius_m: Self::DEFAULT_MARK_RADIUS_M,
            ellipse_axes_m: Self::DEFAULT_ELLIPSE_AXES_M,
        }
    }

    /// Refuses a spec whose image or marks cannot be drawn, including one whose derived
    /// sizes overflow: an infinite image side left every image blank, and a mark reaching
    /// infinitely far lit every pixel for a point anywhere.
    pub fn validate(&self) -> Result<(), SpecError> {
        if self.size == 0 || self.size > MAX_SIZE {
            return Err(SpecError::Size(self.size));
        }
        let resolution_m = self.resolution_m;
        if !(resolution_m.is_finite() && resolution_m > 0.0 && (1.0 / resolution_m).is_finite()) {
            return Err(SpecError::Resolution(resolution_m));
        }
        if !self.extent_m().is_finite() {
            return Err(SpecError::Extent {
                size: self.size,
                resolution_m,
            });
        }
        for (key, value) in [
            ("mark_radius_m", self.mark_radius_m),
            ("ellipse_axes_m", self.ellipse_axes_m[0]),
            ("ellipse_axes_m", self.ellipse_axes_m[1]),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(SpecError::MarkSize { key, value });
            }
            if value / resolution_m > MAX_SIZE as f64 {
                return Err(SpecError::MarkReach {
                    key,
                    value,
                    resolution_m,
                });
            }
        }
        Ok(())
    }

    /// Side of the image in metres.
    pub fn extent_m(&self) -> f64 {
        self.size as f64 * self.resolution_m
    }

    /// An all-zero image of this spec's size.
    pub fn blank_image(&self) -> Array2<f32> {
        Array2::zeros((self.size, self.size))
    }
}

macro_rules! names {
    ($ty:ty, $what:literal, $($variant:path => $name:literal),+) => {
        impl $ty {
            pub const fn name(self) -> &'static str {
                match self { $($variant => $name),+ }
            }
        }
        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }
        impl FromStr for $ty {
            type Err = SpecError;
            fn from_str(s: &str) -> Result<Self, SpecError> {
                match s {
                    $($name => Ok($variant),)+
                    _ => Err(SpecError::UnknownName {
                        what: $what,
                        value: s.to_string(),
                        expected: concat!($($name, " "),+),
                    }),
                }
            }
        }
    };
}

names!(RepresentationKind, "representation",
    RepresentationKind::BooleanGrid => "boolean_grid",
    RepresentationKind::Circles => "circles",
    RepresentationKind::Ellipses => "ellipses");
names!(Framing, "framing",
    Framing::RoomFixed => "room_fixed",
    Framing::PersonCentred => "person_centred");

/// Renders point sets into images of one spec. Holds only the spec's derived constants, so
/// one renderer serves any number of images.
#[derive(Debug, Clone)]
pub struct Renderer {
    spec: RepresentationSpec,
    half_extent: f64,
    inv_res: f64,
}

impl Renderer {
    pub fn new(spec: RepresentationSpec) -> Result<Self, SpecError> {
        spec.validate()?;
        Ok(Self {
            spec,
            half_extent: spec.extent_m() / 2.0,
            inv_res: 1.0 / spec.resolution_m,
        })
    }

    pub fn spec(&self) -> &RepresentationSpec {
        &self.spec
    }

    /// Clears `image` and draws `points` (map frame) into it, centred at `centre`. `sensor`
    /// is the Lidar's position in the map (orients the ellipses). Returns how many points
    /// landed in the image. `image` must be `size x size` (an error-free precondition checked
    /// by a debug assertion; the classifier allocates it from the same spec).
    pub fn render(
        &self,
        points: impl IntoIterator<Item = DVec2>,
        centre: DVec2,
        sensor: DVec2,
        mut image: ArrayViewMut2<'_, f32>,
    ) -> usize {
        let n = self.spec.size;
        debug_assert_eq!(image.dim(), (n, n));
        image.fill(0.0);
        let origin = centre - DVec2::splat(self.half_extent);
        if !origin.is_finite() {
            return 0;
        }
        let mut inside = 0;
        for p in points {
            if !p.is_finite() {
                continue;
            }
            // Position in pixel units from the image corner.
            let u = (p - origin) * self.inv_res;
            let (col, row) = (u.x.floor(), u.y.floor());
            let in_image = col >= 0.0 && row >= 0.0 && col < n as f64 && row < n as f64;
            if in_image {
                inside += 1;
                image[[row as usize, col as usize]] = 1.0;
            }
            match self.spec.kind {
                RepresentationKind::BooleanGrid => {}
                RepresentationKind::Circles => {
                    let r = self.spec.mark_radius_m * self.inv_res;
                    self.fill_mark(&mut image, u, r, |d| d.length_squared() <= r * r);
                }
                RepresentationKind::Ellipses => {
                    let [a, b] = self.spec.ellipse_axes_m.map(|m| m * self.inv_res);
                    let along = (p - sensor).try_normalize().unwrap_or(DVec2::X);
                    let across = along.perp();
                    self.fill_mark(&mut image, u, a.max(b), |d| {
                        let (s, t) = (d.dot(along), d.dot(across));
                        // Written without division so zero-length axes are safe.
                        (s * b).powi(2) + (t * a).powi(2) <= (a * b).powi(2)
                    });
                }
            }
        }
        inside
    }

    /// Sets every pixel whose centre lies within `reach` (pixel units) of `u` and passes
    /// `inside(centre - u)`, visiting only the bounding box clipped to the image.
    fn fill_mark(
        &self,
        image: &mut ArrayViewMut2<'_, f32>,
        u: DVec2,
        reach: f64,
        inside: impl Fn(DVec2) -> bool,
    ) {
        let n = self.spec.size as f64;
        let lo = |v: f64| (v - reach - 0.5).ceil().clamp(0.0, n);
        let hi = |v: f64| (v + reach - 0.5).floor().clamp(-1.0, n - 1.0);
        let (c0, c1, r0, r1) = (lo(u.x), hi(u.x), lo(u.y), hi(u.y));
        if c1 < c0 || r1 < r0 {
            return;
        }
        for row in r0 as usize..=r1 as usize {
            for col in c0 as usize..=c1 as usize {
                let d = DVec2::new(col as f64 + 0.5, row as f64 + 0.5) - u;
                if inside(d) {
                    image[[row, col]] = 1.0;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use proptest::prelude::*;

    fn spec(kind: RepresentationKind) -> RepresentationSpec {
        RepresentationSpec::new(kind, Framing::PersonCentred, 32, 0.05)
    }

    fn render(kind: RepresentationKind, points: &[DVec2]) -> (Array2<f32>, usize) {
        let r = Renderer::new(spec(kind)).unwrap();
        let mut img = r.spec().blank_image();
        let n = r.render(
            points.iter().copied(),
            DVec2::ZERO,
            DVec2::new(-3.0, 0.0),
            img.view_mut(),
        );
        (img, n)
    }

    fn lit(img: &Array2<f32>) -> usize {
        img.iter().filter(|&&v| v == 1.0).count()
    }

    #[test]
    fn boolean_grid_sets_the_cell_of_each_point() {
        // Image spans [-0.8, 0.8) in x and y; cell 16 starts at 0.0.
        let (img, n) = render(
            RepresentationKind::BooleanGrid,
            &[DVec2::new(0.01, 0.01), DVec2::new(-0.79, 0.12)],
        );
        assert_eq!(n, 2);
        assert_eq!(img[[16, 16]], 1.0);
        assert_eq!(img[[18, 0]], 1.0);
        assert_eq!(lit(&img), 2);
    }

    #[test]
    fn points_outside_and_non_finite_are_dropped() {
        let pts = [
            DVec2::new(0.8, 0.0), // right edge is exclusive
            DVec2::new(-0.81, 0.0),
            DVec2::new(0.0, 5.0),
            DVec2::new(f64::NAN, 0.0),
            DVec2::new(0.0, f64::INFINITY),
        ];
        for kind in [
            RepresentationKind::BooleanGrid,
            RepresentationKind::Circles,
            RepresentationKind::Ellipses,
        ] {
            let (img, n) = render(kind, &pts);
            assert_eq!(n, 0, "{kind}");
            // Marks of points just outside may reach in; far and non-finite ones never do.
            if kind == RepresentationKind::BooleanGrid {
                assert_eq!(lit(&img), 0);
            }
            assert!(img.iter().all(|v| *v == 0.0 || *v == 1.0));
        }
    }

    #[test]
    fn circle_is_a_disc_of_the_configured_radius() {
        // Radius 0.05 m = 1 pixel around a pixel centre: the centre and its 4 neighbours.
        let (img, _) = render(RepresentationKind::Circles, &[DVec2::new(0.025, 0.025)]);
        assert_eq!(lit(&img), 5);
        for (r, c) in [(16, 16), (15, 16), (17, 16), (16, 15), (16, 17)] {
            assert_eq!(img[[r, c]], 1.0);
        }
    }

    #[test]
    fn ellipse_is_elongated_along_the_beam() {
        // Sensor on the -x side: the beam runs along x, so the mark is wider than tall.
        let (img, _) = render(RepresentationKind::Ellipses, &[DVec2::new(0.025, 0.025)]);
        let row: usize = (0..32).filter(|&c| img[[16, c]] == 1.0).count();
        let col: usize = (0..32).filter(|&r| img[[r, 16]] == 1.0).count();
        assert!(row > col, "along beam {row} px, across {col} px");
        assert_eq!((row, col), (3, 1));
    }

    #[test]
    fn ellipse_with_point_at_the_sensor_is_still_drawn() {
        let r = Renderer::new(spec(RepresentationKind::Ellipses)).unwrap();
        let mut img = r.spec().blank_image();
        let n = r.render([DVec2::ZERO], DVec2::ZERO, DVec2::ZERO, img.view_mut());
        assert_eq!(n, 1);
        // The beam's direction falls back to x: the ellipse, not only the point's own cell.
        assert_eq!(lit(&img), 4);
    }

    #[test]
    fn render_clears_the_previous_image() {
        let r = Renderer::new(spec(RepresentationKind::Circles)).unwrap();
        let mut img = r.spec().blank_image();
        r.render(
            [DVec2::new(0.3, 0.3)],
            DVec2::ZERO,
            DVec2::ZERO,
            img.view_mut(),
        );
        assert!(lit(&img) > 0);
        r.render(std::iter::empty(), DVec2::ZERO, DVec2::ZERO, img.view_mut());
        assert_eq!(lit(&img), 0);
    }

    #[test]
    fn centre_moves_the_image() {
        let r = Renderer::new(spec(RepresentationKind::BooleanGrid)).unwrap();
        let mut img = r.spec().blank_image();
        let c = DVec2::new(10.0, -4.0);
        r.render([c + DVec2::new(0.01, 0.01)], c, DVec2::ZERO, img.view_mut());
        assert_eq!(img[[16, 16]], 1.0);
    }

    #[test]
    fn invalid_specs_are_rejected_with_the_reason() {
        let mut s = spec(RepresentationKind::Circles);
        s.size = 0;
        assert_eq!(Renderer::new(s).unwrap_err(), SpecError::Size(0));
        let mut s = spec(RepresentationKind::Circles);
        s.resolution_m = f64::NAN;
        assert!(matches!(
            Renderer::new(s).unwrap_err(),
            SpecError::Resolution(_)
        ));
        let mut s = spec(RepresentationKind::Circles);
        s.mark_radius_m = -1.0;
        assert!(matches!(
            Renderer::new(s).unwrap_err(),
            SpecError::MarkSize { .. }
        ));
    }

    #[test]
    fn each_refusal_names_its_setting() {
        let refusal = |change: fn(&mut RepresentationSpec)| {
            let mut s = spec(RepresentationKind::Ellipses);
            change(&mut s);
            s.validate().unwrap_err().to_string()
        };
        for (message, setting) in [
            (refusal(|s| s.size = 0), "size = 0"),
            (refusal(|s| s.resolution_m = 0.0), "resolution_m = 0"),
            (refusal(|s| s.mark_radius_m = -1.0), "mark_radius_m = -1"),
            (
                refusal(|s| s.ellipse_axes_m = [0.08, -0.03]),
                "ellipse_axes_m = -0.03",
            ),
        ] {
            assert!(message.starts_with(setting), "{message}");
        }
    }

    #[test]
    fn specs_whose_derived_sizes_overflow_are_refused() {
        // Accepted before: a mark reaching 1e310 pixels lit all 64 pixels for a point 1e300 m
        // away, a resolution of 1e-310 m has infinite pixels per metre, and an image side of
        // 1024 x 1e306 m is infinite (every image came out blank).
        let mut s =
            RepresentationSpec::new(RepresentationKind::Circles, Framing::RoomFixed, 8, 1e-10);
        s.mark_radius_m = 1e300;
        let e = s.validate().unwrap_err();
        assert!(
            matches!(
                e,
                SpecError::MarkReach {
                    key: "mark_radius_m",
                    ..
                }
            ),
            "{e}"
        );
        s.mark_radius_m = 0.05;
        s.resolution_m = 1e-310;
        assert_eq!(s.validate(), Err(SpecError::Resolution(1e-310)));
        let s = RepresentationSpec::new(
            RepresentationKind::BooleanGrid,
            Framing::RoomFixed,
            1024,
            1e306,
        );
        assert!(matches!(
            s.validate(),
            Err(SpecError::Extent { size: 1024, .. })
        ));
        let mut s =
            RepresentationSpec::new(RepresentationKind::Ellipses, Framing::RoomFixed, 8, 0.05);
        s.ellipse_axes_m = [0.08, 60.0];
        let e = s.validate().unwrap_err();
        assert!(
            matches!(
                e,
                SpecError::MarkReach {
                    key: "ellipse_axes_m",
                    ..
                }
            ),
            "{e}"
        );
        // At the bounds, a point far away lights nothing and one at the centre is drawn.
        for kind in [RepresentationKind::Circles, RepresentationKind::Ellipses] {
            let mut s = RepresentationSpec::new(kind, Framing::RoomFixed, 8, 1e-10);
            s.mark_radius_m = 1e-10 * MAX_SIZE as f64;
            s.ellipse_axes_m = [s.mark_radius_m, s.mark_radius_m / 2.0];
            let r = Renderer::new(s).unwrap();
            let mut img = s.blank_image();
            let far = DVec2::splat(1e300);
            assert_eq!(r.render([far], DVec2::ZERO, DVec2::ZERO, img.view_mut()), 0);
            assert_eq!(lit(&img), 0, "{kind}");
            let n = r.render([DVec2::ZERO], DVec2::ZERO, DVec2::X, img.view_mut());
            assert_eq!((n, lit(&img)), (1, 64), "{kind}");
        }
    }

    #[test]
    fn names_round_trip_and_unknown_names_are_explained() {
        for k in [
            RepresentationKind::BooleanGrid,
            RepresentationKind::Circles,
            RepresentationKind::Ellipses,
        ] {
            assert_eq!(k.name().parse::<RepresentationKind>().unwrap(), k);
        }
        for f in [Framing::RoomFixed, Framing::PersonCentred] {
            assert_eq!(f.name().parse::<Framing>().unwrap(), f);
        }
        let e = "squares"
            .parse::<RepresentationKind>()
            .unwrap_err()
            .to_string();
        assert!(e.contains("squares") && e.contains("boolean_grid"), "{e}");
    }

    fn any_kind() -> impl Strategy<Value = RepresentationKind> {
        prop_oneof![
            Just(RepresentationKind::BooleanGrid),
            Just(RepresentationKind::Circles),
            Just(RepresentationKind::Ellipses)
        ]
    }

    fn any_coordinate() -> impl Strategy<Value = f64> {
        prop_oneof![
            -3.0..3.0f64,
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(1e300),
            Just(-1e300),
        ]
    }

    proptest! {
        #[test]
        fn any_points_give_a_binary_image_and_never_panic(
            kind in any_kind(),
            size in 1usize..48,
            res in 0.01f64..0.2,
            pts in proptest::collection::vec((any_coordinate(), any_coordinate()), 0..40),
            centre in (any_coordinate(), any_coordinate()),
            sensor in (any_coordinate(), any_coordinate()),
        ) {
            let s = RepresentationSpec::new(kind, Framing::RoomFixed, size, res);
            let r = Renderer::new(s).unwrap();
            let mut img = s.blank_image();
            let points: Vec<DVec2> = pts.iter().map(|&(x, y)| DVec2::new(x, y)).collect();
            let n = r.render(points.iter().copied(), DVec2::new(centre.0, centre.1),
                DVec2::new(sensor.0, sensor.1), img.view_mut());
            prop_assert!(n <= points.len());
            prop_assert!(img.iter().all(|v| *v == 0.0 || *v == 1.0));
            // Every point counted inside lights at least its own cell.
            prop_assert!(img.iter().filter(|v| **v == 1.0).count() >= n.min(1));
        }

        #[test]
        fn boolean_grid_lights_exactly_the_cells_of_inside_points(
            cells in proptest::collection::vec((-4i32..36, -4i32..36, 0.05f64..0.95, 0.05f64..0.95), 0..30),
        ) {
            // Points well inside a cell (never on a boundary), cells partly outside the image.
            let s = spec(RepresentationKind::BooleanGrid);
            let r = Renderer::new(s).unwrap();
            let mut img = s.blank_image();
            let points: Vec<DVec2> = cells.iter()
                .map(|&(c, r, fx, fy)| DVec2::new((c as f64 + fx) * 0.05 - 0.8, (r as f64 + fy) * 0.05 - 0.8))
                .collect();
            let n = r.render(points.iter().copied(), DVec2::ZERO, DVec2::ZERO, img.view_mut());
            let mut expected = Array2::<f32>::zeros((32, 32));
            let mut inside = 0;
            for &(c, r, _, _) in &cells {
                if (0..32).contains(&c) && (0..32).contains(&r) {
                    expected[[r as usize, c as usize]] = 1.0;
                    inside += 1;
                }
            }
            prop_assert_eq!(n, inside);
            prop_assert_eq!(img, expected);
        }
    }
}
