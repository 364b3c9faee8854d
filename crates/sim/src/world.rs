//! The static room: walls and furniture turned into footprints (for planning and checks) and
//! into what the Lidar plane cuts (segments and circles for ray casting).

use glam::DVec2;

use crate::scene::{Furniture, Legged, Scene};
use crate::shapes::{Shape, point_in_polygon, segments_cross_outline};

/// What a beam hit, or why it returned nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum BeamLabel {
    /// Nothing within range.
    Nothing = 0,
    Wall = 1,
    Furniture = 2,
    Person = 3,
    /// Noise: the return was lost (+inf).
    Missing = 4,
    /// Noise: a multipath return, the range of a point at another angle.
    Wrong = 5,
}

/// A straight piece of wall or furniture edge in the Lidar plane.
#[derive(Debug, Clone, Copy)]
pub struct Segment {
    pub a: DVec2,
    pub b: DVec2,
    pub label: BeamLabel,
}

/// A round cross-section in the Lidar plane (cylinder, table or chair leg).
#[derive(Debug, Clone, Copy)]
pub struct Circle {
    pub center: DVec2,
    pub radius: f64,
}

/// One piece of furniture's footprints.
#[derive(Debug, Clone)]
pub struct FurnitureShapes {
    pub name: String,
    /// What blocks a person (the whole top for tables and chairs).
    pub person_blocks: Vec<Shape>,
    /// What blocks the robot, which drives under tables and chairs (their legs only) whose
    /// top is above its Lidar ([`World::from_parts`] makes a lower top block it whole).
    pub robot_blocks: Vec<Shape>,
    /// Top height; only parts reaching above the Lidar plane are seen.
    pub height: f64,
}

/// The room as the simulator uses it.
#[derive(Debug, Clone)]
pub struct World {
    pub outline: Vec<DVec2>,
    pub furniture: Vec<FurnitureShapes>,
    /// Everything the Lidar plane cuts, as segments (walls, box and polygon edges) ...
    pub segments: Vec<Segment>,
    /// ... and circles (cylinders, legs).
    pub circles: Vec<Circle>,
    pub lidar_height: f64,
}

fn to_v(p: [f64; 2]) -> DVec2 {
    DVec2::new(p[0], p[1])
}

/// Corners of a `size` rectangle centred at `center`, turned by `yaw_deg`, counter-clockwise.
pub fn rectangle(center: [f64; 2], size: [f64; 2], yaw_deg: f64) -> Vec<DVec2> {
    let (s, c) = yaw_deg.to_radians().sin_cos();
    let (hx, hy) = (size[0] / 2.0, size[1] / 2.0);
    [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
        .into_iter()
        .map(|(x, y)| to_v(center) + DVec2::new(c * x - s * y, s * x + c * y))
        .collect()
}

fn legs(l: &Legged) -> Vec<Shape> {
    let inner = [l.size[0] - 2.0 * l.leg_inset, l.size[1] - 2.0 * l.leg_inset];
    rectangle(l.center, inner, l.yaw_deg)
        .into_iter()
        .map(|center| Shape::Circle {
            center,
            radius: l.leg_radius,
        })
        .collect()
}

/// A polygon made counter-clockwise (edges then face outward consistently).
fn ccw(mut poly: Vec<DVec2>) -> Vec<DVec2> {
    if crate::shapes::polygon_area2(&poly) < 0.0 {
        poly.reverse();
    }
    poly
}

impl FurnitureShapes {
    pub fn new(f: &Furniture) -> Self {
        let name = f.name().to_string();
        match f {
            Furniture::Box {
                center,
                size,
                yaw_deg,
                height,
                ..
            } => {
                let s = vec![Shape::Polygon(rectangle(*center, *size, *yaw_deg))];
                Self {
                    name,
                    person_blocks: s.clone(),
                    robot_blocks: s,
                    height: *height,
                }
            }
            Furniture::Cylinder {
                center,
                radius,
                height,
                ..
            } => {
                let s = vec![Shape::Circle {
                    center: to_v(*center),
                    radius: *radius,
                }];
                Self {
                    name,
                    person_blocks: s.clone(),
                    robot_blocks: s,
                    height: *height,
                }
            }
            Furniture::Polygon { points, height, .. } => {
                let s = vec![Shape::Polygon(ccw(points
                    .iter()
                    .copied()
                    .map(to_v)
                    .collect()))];
                Self {
                    name,
                    person_blocks: s.clone(),
                    robot_blocks: s,
                    height: *height,
                }
            }
            Furniture::Table(l) | Furniture::Chair(l) => Self {
                name,
                person_blocks: vec![Shape::Polygon(rectangle(l.center, l.size, l.yaw_deg))],
                robot_blocks: legs(l),
                height: l.height,
            },
        }
    }
}

impl World {
    /// Builds the room of a scene, cut at the robot's Lidar height.
    pub fn new(scene: &Scene) -> Self {
        let outline = ccw(scene.room.outline.iter().copied().map(to_v).collect());
        let furniture: Vec<FurnitureShapes> =
            scene.furniture.iter().map(FurnitureShapes::new).collect();
        Self::from_parts(outline, furniture, scene.robot.lidar_height)
    }

    /// The room from its outline and footprints, cut at `lidar_height`. A piece no higher
    /// than the Lidar blocks the robot with its whole footprint: a table or chair top that
    /// low is no top to drive under (the Lidar turret would go through it).
    pub fn from_parts(
        outline: Vec<DVec2>,
        mut furniture: Vec<FurnitureShapes>,
        lidar_height: f64,
    ) -> Self {
        for f in &mut furniture {
            if f.height <= lidar_height {
                f.robot_blocks.clone_from(&f.person_blocks);
            }
        }
        let n = outline.len();
        let mut segments: Vec<Segment> = (0..n)
            .map(|i| Segment {
                a: outline[i],
                b: outline[(i + 1) % n],
                label: BeamLabel::Wall,
            })
            .collect();
        let mut circles = Vec::new();
        for f in &furniture {
            // Legs and solids reach from the floor to `height`: seen when above the plane.
            if f.height <= lidar_height {
                continue;
            }
            for shape in &f.robot_blocks {
                match shape {
                    Shape::Polygon(p) => {
                        let m = p.len();
                        segments.extend((0..m).map(|i| Segment {
                            a: p[i],
                            b: p[(i + 1) % m],
                            label: BeamLabel::Furniture,
                        }));
                    }
                    Shape::Circle { center, radius } => circles.push(Circle {
                        center: *center,
                        radius: *radius,
                    }),
                }
            }
        }
        Self {
            outline,
            furniture,
            segments,
            circles,
            lidar_height,
        }
    }

    /// Axis-aligned bounds of the room.
    pub fn bounds(&self) -> (DVec2, DVec2) {
        Shape::Polygon(self.outline.clone()).bounds()
    }

    /// Distance from `p` to the nearest wall, negative outside the room.
    pub fn wall_clearance(&self, p: DVec2) -> f64 {
        -Shape::Polygon(self.outline.clone()).signed_distance(p)
    }

    /// Does the footprint share a point with the floor (the room's outline and inside)?
    pub fn meets_floor(&self, shape: &Shape) -> bool {
        match shape {
            Shape::Circle { center, radius } => self.wall_clearance(*center) >= -radius,
            Shape::Polygon(poly) => {
                let n = poly.len();
                // Edges that touch the walls share a point with them. Otherwise the two
                // outlines are apart: the piece lies inside the room, holds it, or is outside.
                (0..n).any(|i| segments_cross_outline(poly[i], poly[(i + 1) % n], &self.outline))
                    || poly
                        .first()
                        .is_some_and(|p| point_in_polygon(*p, &self.outline))
                    || self
                        .outline
                        .first()
                        .is_some_and(|p| point_in_polygon(*p, poly))
            }
        }
    }

    /// Clearance for the robot at `p`: distance to the nearest wall or robot obstacle
    /// (negative when inside one), and the index of the furniture that is nearest.
    pub fn robot_clearance(&self, p: DVec2) -> (f64, Option<usize>) {
        self.clearance(p, |f| &f.robot_blocks)
    }

    /// Like [`World::robot_clearance`] for a person (tables count whole).
    pub fn person_clearance(&self, p: DVec2) -> (f64, Option<usize>) {
        self.clearance(p, |f| &f.person_blocks)
    }

    fn clearance(
        &self,
        p: DVec2,
        shapes: impl Fn(&FurnitureShapes) -> &Vec<Shape>,
    ) -> (f64, Option<usize>) {
        let mut best = (self.wall_clearance(p), None);
        for (i, f) in self.furniture.iter().enumerate() {
            for s in shapes(f) {
                let d = s.signed_distance(p);
                if d < best.0 {
                    best = (d, Some(i));
                }
            }
        }
        best
    }
}
