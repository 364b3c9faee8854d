//! Top view of a simulation, as a picture (PNG) or an animation (GIF): the map, the robot's
//! path, the person's path coloured by activity (a dot where each activity starts), and scan
//! points coloured by what they hit. Drawn with plotters' bitmap backend; GIF frames encoded
//! by `image`. Colours are fixed (see [`ACTIVITY_COLOURS`] and docs/simulator.md); the legend
//! below the map names each activity's swatch and gives a scale bar. Text is drawn in one
//! embedded font ([`font`]), also used by the CLI's charts.

use std::path::Path;
use std::sync::OnceLock;

use glam::DVec2;
use lidar_har_core::activity::Activity;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::lidar::ScanGeometry;
use crate::map::{FREE, OCCUPIED, OccupancyMap};
use crate::simulator::Frame;
use crate::world::BeamLabel;

/// The family name the embedded font is registered under with plotters.
const FONT_FAMILY: &str = "lidar-har-hack";

/// The pictures' font at `size` pixels: Hack (from `epaint_default_fonts`, MIT + Bitstream
/// Vera licence), embedded so that pictures need no system fonts and look the same
/// everywhere. Registered with plotters' global font table on first use, once.
pub fn font(size: f64) -> Result<FontDesc<'static>, String> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let registered = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(
            FONT_FAMILY,
            FontStyle::Normal,
            epaint_default_fonts::HACK_REGULAR,
        )
        .is_ok()
    });
    if registered {
        Ok((FONT_FAMILY, size).into_font())
    } else {
        Err("the embedded font (Hack, epaint_default_fonts) cannot be read".into())
    }
}

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
    scans: Vec<KeptScan>,
}

/// The scan points of one kept frame, and how long the paths were at that frame (what an
/// animation frame shows).
#[derive(Debug, Clone)]
struct KeptScan {
    robot_len: usize,
    person_len: usize,
    points: Vec<(DVec2, BeamLabel)>,
}

impl Trace {
    /// Keeps the scan points of every `scan_every`-th frame (paths use every frame).
    pub fn new(scan_every: u64) -> Self {
        Self {
            scan_every: scan_every.max(1),
            robot: Vec::new(),
            person: Vec::new(),
            scans: Vec::new(),
        }
    }

    pub fn add(&mut self, frame: &Frame, geometry: &ScanGeometry) {
        self.robot.push(frame.robot.position());
        if let Some(p) = &frame.person {
            self.person.push((p.pose.position(), p.activity));
        }
        if frame.index.is_multiple_of(self.scan_every) {
            let points = frame
                .ranges
                .iter()
                .zip(&frame.labels)
                .enumerate()
                .filter(|(_, (r, _))| r.is_finite())
                .map(|(i, (r, l))| {
                    let a = geometry.angle_min + geometry.angle_increment * i as f64;
                    let p = frame
                        .laser
                        .transform_point(DVec2::from_angle(a) * *r as f64);
                    (p, *l)
                })
                .collect();
            self.scans.push(KeptScan {
                robot_len: self.robot.len(),
                person_len: self.person.len(),
                points,
            });
        }
    }

    /// How many frames an animation of this trace has.
    pub fn animation_frames(&self) -> usize {
        self.scans.len()
    }
}

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
#[error("cannot render {path}: {message}")]
pub struct RenderError {
    pub path: String,
    pub message: String,
}

/// Pixels per metre of the picture (smaller for rooms over 20 m).
const SCALE: f64 = 100.0;
/// The legend's items (each activity's swatch and name, the robot's path, each kind of scan
/// point, then the scale bar) lie in rows below the map, as many to a row as the width holds
/// at this width each.
const LEGEND_ITEM_WIDTH: u32 = 170;
const LEGEND_ROW: u32 = 20;
const LEGEND_ITEMS: u32 = (Activity::COUNT + 1 + SCAN_POINT_KINDS.len() + 1) as u32;
/// The scan points' kinds as the legend names them.
const SCAN_POINT_KINDS: [(BeamLabel, &str); 4] = [
    (BeamLabel::Wall, "scan: wall"),
    (BeamLabel::Furniture, "scan: furniture"),
    (BeamLabel::Person, "scan: person"),
    (BeamLabel::Wrong, "scan: multipath"),
];
/// The robot's path and rings.
const ROBOT_COLOUR: RGBColor = RGBColor(0, 0, 255);
const LEGEND_FONT: f64 = 13.0;
/// A legend swatch's width and height.
const SWATCH: (i32, i32) = (18, 12);

/// Map coordinates to pixels.
struct View {
    origin: DVec2,
    scale: f64,
    /// Picture size without the legend strip.
    width: u32,
    height: u32,
}

impl View {
    fn new(map: &OccupancyMap, max_side_px: f64) -> Self {
        let (w_m, h_m) = (
            map.width as f64 * map.resolution,
            map.height as f64 * map.resolution,
        );
        let scale = SCALE.min(max_side_px / w_m.max(h_m));
        Self {
            origin: map.origin,
            scale,
            width: (w_m * scale).ceil() as u32,
            height: (h_m * scale).ceil() as u32,
        }
    }

    fn size(&self) -> (u32, u32) {
        (self.width, self.height + self.legend_height())
    }

    fn legend_columns(&self) -> u32 {
        (self.width / LEGEND_ITEM_WIDTH).clamp(1, LEGEND_ITEMS)
    }

    fn legend_height(&self) -> u32 {
        LEGEND_ITEMS.div_ceil(self.legend_columns()) * LEGEND_ROW + 8
    }

    /// The box of legend item `k` (activities in class order, then the scale bar):
    /// top left corner and width.
    fn legend_item(&self, k: u32) -> ((i32, i32), i32) {
        let columns = self.legend_columns();
        let width = self.width / columns;
        let x = (k % columns) * width;
        let y = self.height + 4 + (k / columns) * LEGEND_ROW;
        ((x as i32, y as i32), width as i32)
    }

    fn px(&self, p: DVec2) -> (i32, i32) {
        let q = (p - self.origin) * self.scale;
        (
            q.x.round() as i32,
            (self.height as f64 - q.y).round() as i32,
        )
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type DrawResult = Result<(), String>;

fn drawn<E: std::error::Error>(r: Result<(), E>) -> DrawResult {
    r.map_err(|e| e.to_string())
}

/// The scale bar's length in metres: the first of 1, 2, 5, 10, 20, 50 .. m that is at least
/// 40 px long at `scale` pixels per metre.
fn scale_bar_m(scale: f64) -> f64 {
    (0..8)
        .flat_map(|decade| [1.0, 2.0, 5.0].map(|f| f * 10f64.powi(decade)))
        .find(|m| m * scale >= 40.0)
        .unwrap_or(1e8)
}

/// The legend below the map: each activity's swatch and name in class order, the robot's
/// path, the scan points' kinds, then a scale bar.
fn draw_legend(root: &Area, view: &View) -> DrawResult {
    let text = font(LEGEND_FONT)?
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    let middle = LEGEND_ROW as i32 / 2 - 2;
    let mut item = 0;
    let mut next_item = || {
        item += 1;
        view.legend_item(item - 1).0
    };
    let name = |label: &str, (x, y): (i32, i32)| {
        drawn(root.draw(&Text::new(
            label.to_string(),
            (x + 8 + SWATCH.0, y + middle),
            &text,
        )))
    };
    for (a, c) in Activity::ALL.iter().zip(ACTIVITY_COLOURS) {
        let (x, y) = next_item();
        let top = y + middle - SWATCH.1 / 2;
        drawn(root.draw(&Rectangle::new(
            [(x + 4, top), (x + 4 + SWATCH.0, top + SWATCH.1)],
            c.filled(),
        )))?;
        name(a.label(), (x, y))?;
    }
    let (x, y) = next_item();
    drawn(root.draw(&PathElement::new(
        vec![(x + 4, y + middle), (x + 4 + SWATCH.0, y + middle)],
        ROBOT_COLOUR.stroke_width(2),
    )))?;
    name("robot", (x, y))?;
    for (label, label_name) in SCAN_POINT_KINDS {
        let (x, y) = next_item();
        if let Some(c) = label_colour(label) {
            for dx in [4, 10, 16] {
                drawn(root.draw(&Circle::new(
                    (x + 2 + dx, y + middle + dx % 3 - 1),
                    2,
                    c.filled(),
                )))?;
            }
        }
        name(label_name, (x, y))?;
    }
    let (x, y) = next_item();
    let metres = scale_bar_m(view.scale);
    let end = x + 4 + (metres * view.scale).round() as i32;
    let (bar, tick) = (y + middle, SWATCH.1 / 2);
    drawn(root.draw(&PathElement::new(
        vec![(x + 4, bar - tick), (x + 4, bar + tick)],
        BLACK,
    )))?;
    drawn(root.draw(&PathElement::new(
        vec![(end, bar - tick), (end, bar + tick)],
        BLACK,
    )))?;
    drawn(root.draw(&PathElement::new(
        vec![(x + 4, bar), (end, bar)],
        BLACK.stroke_width(2),
    )))?;
    drawn(root.draw(&Text::new(format!("{metres} m"), (end + 4, bar), &text)))
}

/// White page, the map's cells, and the legend.
fn draw_background(root: &Area, view: &View, map: &OccupancyMap) -> DrawResult {
    drawn(root.fill(&WHITE))?;
    let cell = (map.resolution * view.scale).ceil() as i32;
    for j in 0..map.height {
        for i in 0..map.width {
            let colour = match map.data[(j * map.width + i) as usize] {
                OCCUPIED => RGBColor(40, 40, 40),
                FREE => RGBColor(250, 250, 250),
                _ => RGBColor(205, 205, 205),
            };
            let (x, y) =
                view.px(map.origin + DVec2::new(i as f64, j as f64 + 1.0) * map.resolution);
            drawn(root.draw(&Rectangle::new(
                [(x, y), (x + cell, y + cell)],
                colour.filled(),
            )))?;
        }
    }
    draw_legend(root, view)
}

/// Scan points on the map; none below it, where wrong returns beyond the walls fell on the
/// legend's names.
fn draw_points(root: &Area, view: &View, points: &[(DVec2, BeamLabel)]) -> DrawResult {
    for (p, l) in points {
        let (x, y) = view.px(*p);
        if let Some(c) = label_colour(*l).filter(|_| y + 1 < view.height as i32) {
            drawn(root.draw(&Circle::new((x, y), 1, c.filled())))?;
        }
    }
    Ok(())
}

/// The robot's path (blue) and the person's path coloured by activity, with a dot where each
/// activity starts. Dots go over lines, and within each the fall ([`drawn_last`]) over the
/// rest: getting up goes back along the line of the fall, and drawn in time order it hid the
/// fall's segments and dots under its own.
fn draw_paths(
    root: &Area,
    view: &View,
    robot: &[DVec2],
    person: &[(DVec2, Activity)],
) -> DrawResult {
    let path: Vec<(i32, i32)> = robot.iter().map(|p| view.px(*p)).collect();
    drawn(root.draw(&PathElement::new(path, ROBOT_COLOUR.stroke_width(2))))?;
    let starts: Vec<&(DVec2, Activity)> = person
        .iter()
        .enumerate()
        .filter(|(i, (_, a))| *i == 0 || person[i - 1].1 != *a)
        .map(|(_, start)| start)
        .collect();
    for fall in [false, true] {
        for w in person.windows(2).filter(|w| drawn_last(w[1].1) == fall) {
            let c = ACTIVITY_COLOURS[w[1].1.index()];
            drawn(root.draw(&PathElement::new(
                vec![view.px(w[0].0), view.px(w[1].0)],
                c.stroke_width(3),
            )))?;
        }
    }
    for fall in [false, true] {
        for (p, a) in starts.iter().filter(|(_, a)| drawn_last(*a) == fall) {
            let colour = ACTIVITY_COLOURS[a.index()];
            drawn(root.draw(&Circle::new(view.px(*p), 6, colour.filled())))?;
            drawn(root.draw(&Circle::new(view.px(*p), 6, BLACK.stroke_width(1))))?;
        }
    }
    Ok(())
}

/// The fall: falling down and lying down, drawn over the rest of the person's path.
fn drawn_last(activity: Activity) -> bool {
    matches!(activity, Activity::FallingDown | Activity::LyingDown)
}

/// Where robot and person are now: a blue ring, and a ring in the current activity's colour
/// (rings, so the scan points on the body stay visible).
fn draw_now(
    root: &Area,
    view: &View,
    robot: Option<&DVec2>,
    person: Option<&(DVec2, Activity)>,
) -> DrawResult {
    if let Some(r) = robot {
        drawn(root.draw(&Circle::new(view.px(*r), 9, ROBOT_COLOUR.stroke_width(3))))?;
    }
    if let Some((p, a)) = person {
        drawn(root.draw(&Circle::new(view.px(*p), 16, BLACK.stroke_width(1))))?;
        drawn(root.draw(&Circle::new(
            view.px(*p),
            14,
            ACTIVITY_COLOURS[a.index()].stroke_width(4),
        )))?;
    }
    Ok(())
}

fn render_error(path: &Path) -> impl Fn(String) -> RenderError + '_ {
    move |message| RenderError {
        path: path.display().to_string(),
        message,
    }
}

/// Draws the picture as a PNG at `path`: every kept scan, the whole paths.
pub fn render_png(path: &Path, map: &OccupancyMap, trace: &Trace) -> Result<(), RenderError> {
    let view = View::new(map, 2000.0);
    let root = BitMapBackend::new(path, view.size()).into_drawing_area();
    draw_background(&root, &view, map)
        .and_then(|_| {
            trace
                .scans
                .iter()
                .try_for_each(|scan| draw_points(&root, &view, &scan.points))
        })
        .and_then(|_| draw_paths(&root, &view, &trace.robot, &trace.person))
        .and_then(|_| drawn(root.present()))
        .map_err(render_error(path))
}

/// The shortest time between an animation's frames: browsers play shorter GIF delays
/// (10 ms, 0) as 100 ms.
pub const MIN_FRAME_DELAY_MS: f64 = 20.0;

/// Every how many scans an animation keeps one, for `scans` scans `scan_time` seconds apart
/// played `speed_up` times faster than real time: at most `frames` frames, and at least
/// [`MIN_FRAME_DELAY_MS`] between them (a short run gets fewer frames, not a slower play).
pub fn animation_scan_every(scans: u64, scan_time: f64, frames: u64, speed_up: f64) -> u64 {
    let by_count = scans.div_ceil(frames.max(1));
    // A hair below the ratio, so that a whole number (80 ms of 20 ms scans) stays whole.
    let by_delay = (MIN_FRAME_DELAY_MS * speed_up / (scan_time * 1000.0) - 1e-9).ceil();
    by_count.max(by_delay as u64).max(1)
}

/// Draws an animated GIF at `path`, one frame per kept scan: that scan's points, the paths
/// so far, where robot and person are, `frame_delay_ms` apart (at least
/// [`MIN_FRAME_DELAY_MS`]). GIF delays are whole centiseconds: each frame's is rounded so
/// that the time played up to its end is within 5 ms of the exact one (a delay of 162.5 ms
/// became 160 on every frame).
pub fn render_gif(
    path: &Path,
    map: &OccupancyMap,
    trace: &Trace,
    frame_delay_ms: f64,
) -> Result<(), RenderError> {
    use image::codecs::gif::{GifEncoder, Repeat};

    let err = render_error(path);
    if trace.scans.is_empty() {
        return Err(err("the trace holds no scan to animate".into()));
    }
    let view = View::new(map, 800.0);
    let (w, h) = view.size();
    let mut background = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut background, (w, h)).into_drawing_area();
        draw_background(&root, &view, map)
            .and_then(|_| drawn(root.present()))
            .map_err(&err)?;
    }
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    let mut encoder = GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
    encoder
        .set_repeat(Repeat::Infinite)
        .map_err(|e| err(e.to_string()))?;
    let delay_cs = frame_delay_ms.max(MIN_FRAME_DELAY_MS) / 10.0;
    // Centiseconds played by the end of frame `k`.
    let played = |k: usize| (k as f64 * delay_cs).round() as u32;
    for (k, scan) in trace.scans.iter().enumerate() {
        let delay = image::Delay::from_numer_denom_ms(10 * (played(k + 1) - played(k)), 1);
        let mut pixels = background.clone();
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
            let robot = &trace.robot[..scan.robot_len];
            let person = &trace.person[..scan.person_len];
            draw_paths(&root, &view, robot, person)
                .and_then(|_| draw_now(&root, &view, robot.last(), person.last()))
                .and_then(|_| draw_points(&root, &view, &scan.points))
                .and_then(|_| drawn(root.present()))
                .map_err(&err)?;
        }
        let rgb = image::RgbImage::from_raw(w, h, pixels)
            .ok_or_else(|| err("frame buffer size mismatch".into()))?;
        let frame =
            image::Frame::from_parts(image::DynamicImage::from(rgb).to_rgba8(), 0, 0, delay);
        encoder
            .encode_frame(frame)
            .map_err(|e| err(e.to_string()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Scene, Simulator};
    use image::AnimationDecoder;

    fn living_room_trace(seconds: f64, scan_every: u64) -> (OccupancyMap, Trace) {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/scenes/living_room.yaml"
        );
        let mut scene = Scene::load(Path::new(path)).unwrap();
        scene.duration = seconds;
        let mut sim = Simulator::new(scene, 1).unwrap();
        let geometry = sim.scan_geometry();
        let mut trace = Trace::new(scan_every);
        while let Some(frame) = sim.step() {
            trace.add(&frame, &geometry);
        }
        (OccupancyMap::from_world(sim.world(), 0.05), trace)
    }

    fn has_colour(pixels: impl IntoIterator<Item = [u8; 3]>, c: RGBColor) -> bool {
        pixels.into_iter().any(|p| p == [c.0, c.1, c.2])
    }

    #[test]
    fn png_shows_map_scan_points_and_the_activity_legend() {
        let (map, trace) = living_room_trace(2.0, 10);
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("top.png");
        render_png(&png, &map, &trace).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        let view = View::new(&map, 2000.0);
        assert_eq!(img.dimensions(), view.size());
        let pixels = || img.pixels().map(|p| p.0);
        assert!(has_colour(pixels(), RGBColor(40, 40, 40)), "walls");
        assert!(has_colour(pixels(), RGBColor(90, 90, 90)), "wall hits");
        assert!(has_colour(pixels(), RGBColor(220, 0, 0)), "person hits");
        for c in ACTIVITY_COLOURS {
            assert!(has_colour(pixels(), c), "legend swatch {c:?}");
        }
    }

    /// Pixels darker than mid grey (text and outlines) in a box of the picture.
    fn dark_pixels(img: &image::RgbImage, (x0, y0): (i32, i32), (w, h): (i32, i32)) -> Vec<u32> {
        (y0..y0 + h)
            .flat_map(|y| (x0..x0 + w).map(move |x| (x as u32, y as u32)))
            .map(|(x, y)| img.get_pixel(x, y).0)
            .map(|p| u32::from(p.iter().all(|v| *v < 128)))
            .collect()
    }

    /// The legend was a strip of bare swatches: a reader needed docs/simulator.md to know
    /// which colour was which activity. Each swatch now has its name beside it (text where
    /// the name goes, a different shape for each name), and a scale bar ends the legend.
    #[test]
    fn each_legend_swatch_is_named_and_the_legend_has_a_scale() {
        let (map, mut trace) = living_room_trace(0.5, 10);
        // Wrong returns beyond the map's bottom edge, where the legend is.
        let view = View::new(&map, 2000.0);
        let below = (0..view.width)
            .map(|x| {
                (
                    map.origin + DVec2::new(f64::from(x) / view.scale, -0.15),
                    BeamLabel::Wrong,
                )
            })
            .collect();
        trace.scans.push(KeptScan {
            robot_len: 0,
            person_len: 0,
            points: below,
        });
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("top.png");
        render_png(&png, &map, &trace).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        let wrong = label_colour(BeamLabel::Wrong).unwrap();
        // The multipath item's own marker (the legend's last kind of scan point) aside.
        let ((mx, my), _) = view.legend_item(LEGEND_ITEMS - 2);
        let marker = |x: u32, y: u32| {
            (mx..mx + 6 + SWATCH.0).contains(&(x as i32))
                && (my..my + LEGEND_ROW as i32).contains(&(y as i32))
        };
        let on_legend = img
            .enumerate_pixels()
            .filter(|(x, y, p)| {
                *y >= view.height && !marker(*x, *y) && p.0 == [wrong.0, wrong.1, wrong.2]
            })
            .count();
        assert_eq!(on_legend, 0, "scan points drawn over the legend");
        let mut names = Vec::new();
        for (k, a) in Activity::ALL.iter().enumerate() {
            let ((x, y), width) = view.legend_item(k as u32);
            let swatch = ACTIVITY_COLOURS[a.index()];
            let at = img
                .get_pixel((x + 4 + SWATCH.0 / 2) as u32, (y + 8) as u32)
                .0;
            assert_eq!(at, [swatch.0, swatch.1, swatch.2], "{} swatch", a.label());
            let name = dark_pixels(
                &img,
                (x + 6 + SWATCH.0, y),
                (width - 8 - SWATCH.0, LEGEND_ROW as i32),
            );
            let count: u32 = name.iter().sum();
            assert!(count > 20, "{}: {count} text pixels", a.label());
            assert!(!names.contains(&name), "{} drawn as another", a.label());
            names.push(name);
        }
        // The robot's path and the scan points' kinds: each marker in its colour, then a name.
        let markers = std::iter::once(ROBOT_COLOUR)
            .chain(SCAN_POINT_KINDS.map(|(label, _)| label_colour(label).unwrap()));
        for (k, colour) in (Activity::COUNT as u32..).zip(markers) {
            let ((x, y), width) = view.legend_item(k);
            let img = &img;
            let marker = (x..x + 6 + SWATCH.0).flat_map(|px| {
                (y..y + LEGEND_ROW as i32).map(move |py| img.get_pixel(px as u32, py as u32).0)
            });
            assert!(has_colour(marker, colour), "legend item {k}: its marker");
            let name = dark_pixels(
                img,
                (x + 6 + SWATCH.0, y),
                (width - 8 - SWATCH.0, LEGEND_ROW as i32),
            );
            assert!(name.iter().sum::<u32>() > 20, "legend item {k}: its name");
            assert!(!names.contains(&name), "legend item {k} drawn as another");
            names.push(name);
        }
        let ((x, y), width) = view.legend_item(LEGEND_ITEMS - 1);
        let bar = dark_pixels(&img, (x, y), (width, LEGEND_ROW as i32));
        let bar_px = (scale_bar_m(view.scale) * view.scale) as u32;
        assert!(
            bar.iter().sum::<u32>() > 2 * bar_px,
            "scale bar and its length"
        );
        assert_eq!(scale_bar_m(100.0), 1.0);
        assert_eq!(scale_bar_m(30.0), 2.0);
        assert_eq!(scale_bar_m(4.0), 10.0);
    }

    /// Getting up went back along the line of the fall and, drawn after it, hid the falling
    /// and lying colours (segments and dots) under its own: the demo's picture showed no fall.
    #[test]
    fn the_fall_stays_visible_under_a_getting_up_path_that_goes_back_over_it() {
        let (map, _) = living_room_trace(0.1, 1);
        let start = map.origin + DVec2::new(1.0, 1.0);
        let step = |k: usize| start + DVec2::new(0.05 * k as f64, 0.0);
        let mut trace = Trace::new(1);
        trace.person.push((start, Activity::Standing));
        trace
            .person
            .extend((0..=20).map(|k| (step(k), Activity::FallingDown)));
        trace
            .person
            .extend((0..10).map(|_| (step(20), Activity::LyingDown)));
        trace
            .person
            .extend((0..=20).rev().map(|k| (step(k), Activity::GettingUp)));
        trace.person.push((start, Activity::Standing));
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("fall.png");
        render_png(&png, &map, &trace).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        // The map only: the legend strip below it has every colour.
        let map_height = View::new(&map, 2000.0).height;
        let pixels = || {
            img.enumerate_pixels()
                .filter(|(_, y, _)| *y < map_height)
                .map(|(_, _, p)| p.0)
        };
        for fall in [Activity::FallingDown, Activity::LyingDown] {
            let colour = ACTIVITY_COLOURS[fall.index()];
            assert!(has_colour(pixels(), colour), "{} hidden", fall.label());
        }
    }

    #[test]
    fn gif_has_one_frame_per_kept_scan_and_moves() {
        let (map, trace) = living_room_trace(2.0, 10);
        assert_eq!(trace.animation_frames(), 4);
        let dir = tempfile::tempdir().unwrap();
        let gif = dir.path().join("top.gif");
        render_gif(&gif, &map, &trace, 100.0).unwrap();
        let file = std::io::BufReader::new(std::fs::File::open(&gif).unwrap());
        let frames = image::codecs::gif::GifDecoder::new(file)
            .unwrap()
            .into_frames()
            .collect_frames()
            .unwrap();
        assert_eq!(frames.len(), 4);
        assert_eq!(frames[0].delay().numer_denom_ms(), (100, 1));
        let (w, h) = View::new(&map, 800.0).size();
        assert_eq!(frames[0].buffer().dimensions(), (w, h));
        assert_ne!(
            frames[0].buffer().as_raw(),
            frames[3].buffer().as_raw(),
            "successive frames differ (scan points, robot)"
        );
    }

    /// A GIF promised at 4x real time with 100 frames: a run of 150 scans kept every scan
    /// (150 frames, 12.5 ms apart, played at the 20 ms floor: 2.5x), and delays off GIF's
    /// 10 ms steps were cut to them on every frame (162.5 ms played as 160).
    #[test]
    fn an_animation_keeps_its_speed_and_at_most_its_frames() {
        for (scans, every) in [(150, 2), (40, 2), (800, 8), (1050, 11), (1300, 13), (1, 2)] {
            let got = animation_scan_every(scans, 0.05, 100, 4.0);
            assert_eq!(got, every, "{scans} scans");
            assert!(scans.div_ceil(got) <= 100);
            assert!(got as f64 * 50.0 / 4.0 >= MIN_FRAME_DELAY_MS);
        }
        // A 1000 Hz Lidar: 80 scans a frame at least.
        assert_eq!(animation_scan_every(1000, 0.001, 100, 4.0), 80);
        let (map, trace) = living_room_trace(2.0, 5);
        let dir = tempfile::tempdir().unwrap();
        let gif = dir.path().join("top.gif");
        render_gif(&gif, &map, &trace, 162.5).unwrap();
        let file = std::io::BufReader::new(std::fs::File::open(&gif).unwrap());
        let delays: Vec<u32> = image::codecs::gif::GifDecoder::new(file)
            .unwrap()
            .into_frames()
            .collect_frames()
            .unwrap()
            .iter()
            .map(|f| f.delay().numer_denom_ms().0)
            .collect();
        assert_eq!(delays.len(), 8);
        let mut played = 0.0;
        for (k, d) in delays.iter().enumerate() {
            played += *d as f64;
            assert!((played - 162.5 * (k + 1) as f64).abs() <= 5.0, "{delays:?}");
        }
    }

    #[test]
    fn an_empty_trace_is_an_error_naming_the_file() {
        let (map, _) = living_room_trace(0.1, 1);
        let e = render_gif(Path::new("/tmp/empty.gif"), &map, &Trace::new(1), 100.0).unwrap_err();
        assert!(e.to_string().contains("/tmp/empty.gif"), "{e}");
        let e = render_png(Path::new("/nonexistent/dir/x.png"), &map, &Trace::new(1)).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/dir/x.png"), "{e}");
    }
}
