//! Top-view picture of a simulation: the map, the robot's path, the person's path coloured
//! by activity (a dot where each activity starts), and scan points coloured by what they hit.
//! Drawn with plotters' bitmap backend. The workspace builds plotters without font support,
//! so the picture has no text: colours are fixed (see [`ACTIVITY_COLOURS`] and
//! docs/simulator.md) and a strip of nine swatches along the bottom, in class order, is the
//! legend.

use std::path::Path;

use glam::DVec2;
use lidar_har_core::activity::Activity;
use plotters::prelude::*;

use crate::lidar::ScanGeometry;
use crate::map::{FREE, OCCUPIED, OccupancyMap};
use crate::simulator::Frame;
use crate::world::BeamLabel;

/// One colour per activity, in class order (crawling .. walking_unsteadily).
pub const ACTIVITY_COLOURS: [RGBColor; Activity::COUNT] = [
    RGBColor(141, 85, 36),  // crawling: brown
    RGBColor(230, 25, 75),  // falling_down: red
    RGBColor(245, 130, 48), // getting_up: orange
    RGBColor(145, 30, 180), // lying_down: purple
    RGBColor(0, 130, 200),  // running: blue
    RGBColor(70, 240, 240), // sitting_on_floor: cyan
    RGBColor(60, 180, 75),  // standing: green
    RGBColor(128, 128, 0),  // walking: olive
    RGBColor(240, 50, 230), // walking_unsteadily: magenta
];

fn label_colour(l: BeamLabel) -> Option<RGBColor> {
    match l {
        BeamLabel::Wall => Some(RGBColor(90, 90, 90)),
        BeamLabel::Furniture => Some(RGBColor(200, 160, 60)),
        BeamLabel::Person => Some(RGBColor(220, 0, 0)),
        BeamLabel::Wrong => Some(RGBColor(255, 0, 255)),
        BeamLabel::Nothing | BeamLabel::Missing => None,
    }
}

/// What a render needs, gathered frame by frame.
#[derive(Debug, Clone)]
pub struct Trace {
    scan_every: u64,
    robot: Vec<DVec2>,
    person: Vec<(DVec2, Activity)>,
    points: Vec<(DVec2, BeamLabel)>,
}

impl Trace {
    /// Keeps the scan points of every `scan_every`-th frame (paths use every frame).
    pub fn new(scan_every: u64) -> Self {
        Self {
            scan_every: scan_every.max(1),
            robot: Vec::new(),
            person: Vec::new(),
            points: Vec::new(),
        }
    }

    pub fn add(&mut self, frame: &Frame, geometry: &ScanGeometry) {
        self.robot.push(frame.robot.position());
        if let Some(p) = &frame.person {
            self.person.push((p.pose.position(), p.activity));
        }
        if frame.index.is_multiple_of(self.scan_every) {
            for (i, (r, l)) in frame.ranges.iter().zip(&frame.labels).enumerate() {
                if r.is_finite() {
                    let a = geometry.angle_min + geometry.angle_increment * i as f64;
                    let p = frame
                        .laser
                        .transform_point(DVec2::from_angle(a) * *r as f64);
                    self.points.push((p, *l));
                }
            }
        }
    }
}

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
#[error("cannot render {path}: {message}")]
pub struct RenderError {
    pub path: String,
    pub message: String,
}

/// Pixels per metre of the picture.
const SCALE: f64 = 100.0;
const LEGEND: u32 = 30;

/// Draws the picture as a PNG at `path`.
pub fn render_png(path: &Path, map: &OccupancyMap, trace: &Trace) -> Result<(), RenderError> {
    let err = |message: String| RenderError {
        path: path.display().to_string(),
        message,
    };
    let (w_m, h_m) = (
        map.width as f64 * map.resolution,
        map.height as f64 * map.resolution,
    );
    let scale = SCALE.min(2000.0 / w_m.max(h_m));
    let (w, h) = ((w_m * scale).ceil() as u32, (h_m * scale).ceil() as u32);
    let root = BitMapBackend::new(path, (w, h + LEGEND)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let px = |p: DVec2| -> (i32, i32) {
        let q = (p - map.origin) * scale;
        (q.x.round() as i32, (h as f64 - q.y).round() as i32)
    };
    let cell = (map.resolution * scale).ceil() as i32;
    for j in 0..map.height {
        for i in 0..map.width {
            let colour = match map.data[(j * map.width + i) as usize] {
                OCCUPIED => RGBColor(40, 40, 40),
                FREE => RGBColor(250, 250, 250),
                _ => RGBColor(205, 205, 205),
            };
            let (x, y) = px(map.origin + DVec2::new(i as f64, j as f64 + 1.0) * map.resolution);
            root.draw(&Rectangle::new(
                [(x, y), (x + cell, y + cell)],
                colour.filled(),
            ))
            .map_err(|e| err(e.to_string()))?;
        }
    }
    for (p, l) in &trace.points {
        if let Some(c) = label_colour(*l) {
            root.draw(&Circle::new(px(*p), 1, c.filled()))
                .map_err(|e| err(e.to_string()))?;
        }
    }
    let robot: Vec<(i32, i32)> = trace.robot.iter().map(|p| px(*p)).collect();
    root.draw(&PathElement::new(
        robot,
        RGBColor(0, 0, 255).stroke_width(2),
    ))
    .map_err(|e| err(e.to_string()))?;
    for w in trace.person.windows(2) {
        let c = ACTIVITY_COLOURS[w[1].1.index()];
        root.draw(&PathElement::new(
            vec![px(w[0].0), px(w[1].0)],
            c.stroke_width(3),
        ))
        .map_err(|e| err(e.to_string()))?;
    }
    // A dot where each activity starts.
    let mut last: Option<Activity> = None;
    for (p, a) in &trace.person {
        if last != Some(*a) {
            root.draw(&Circle::new(
                px(*p),
                6,
                ACTIVITY_COLOURS[a.index()].filled(),
            ))
            .map_err(|e| err(e.to_string()))?;
            root.draw(&Circle::new(px(*p), 6, BLACK.stroke_width(1)))
                .map_err(|e| err(e.to_string()))?;
            last = Some(*a);
        }
    }
    // Legend: the nine activity colours in class order.
    let sw = (w / Activity::COUNT as u32).max(1) as i32;
    for (k, c) in ACTIVITY_COLOURS.iter().enumerate() {
        let x = k as i32 * sw;
        root.draw(&Rectangle::new(
            [(x + 2, h as i32 + 4), (x + sw - 2, (h + LEGEND) as i32 - 4)],
            c.filled(),
        ))
        .map_err(|e| err(e.to_string()))?;
    }
    root.present().map_err(|e| err(e.to_string()))
}
