//! Animated GIFs of a [`Trajectory`] ([`Trajectory::to_gif`]), drawn by the small rasterizer
//! in `raster.rs` and encoded by the `gif` crate.
//!
//! The scene is the HTML player's: every agent geom as a capsule (spheres as discs) coloured
//! by team in Sumo and by agent in Reach, the balls as discs, a 1 m ground grid and, in Sumo,
//! the arena ring about the centre ball. One fixed perspective camera looks down at 45 degrees
//! and frames the bounding box of the whole episode (computed once, so it never jumps).
//! Each frame draws blob shadows on the ground, then the capsules and balls far to near
//! (painter's order by mean depth), each with a dark 1-pixel outline, and on top the task
//! assignment, if one was recorded: a dashed line in each agent's colour from its root body
//! to its entity, as the HTML player marks it. Sixteen fixed colours;
//! after the first frame only the rectangle that changed is stored, unchanged pixels
//! transparent, which keeps a 1000-step episode small.

use super::raster::Canvas;
use super::{AGENT_COLOURS, REACH_BALL_COLOUR, SUMO_BALL_COLOUR, Trajectory};
use crate::tasks::error::TaskError;
use crate::tasks::scene::BALL_RADIUS;
use crate::tasks::spec::TaskKind;
use std::borrow::Cow;

/// Size and timing of [`Trajectory::to_gif`]'s animation (it always loops forever).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GifOptions {
    /// Image width in pixels (at least 1).
    pub width: u16,
    /// Image height in pixels (at least 1).
    pub height: u16,
    /// Keep every `frame_step`-th recorded frame, starting with the first (at least 1).
    pub frame_step: usize,
    /// How long each GIF frame is shown, in centiseconds (at least 1; browsers show delays
    /// below 2 as 10).
    pub delay_cs: u16,
}

impl Default for GifOptions {
    /// 480 x 360 pixels, every 2nd frame shown for 10 cs: at MeBen's 0.05 s control step,
    /// 10 frames per simulated second, played in real time.
    fn default() -> GifOptions {
        GifOptions { width: 480, height: 360, frame_step: 2, delay_cs: 10 }
    }
}

// Palette indices (`PALETTE` below holds their colours).
const BACKGROUND: u8 = 0;
const GRID: u8 = 1;
const SHADOW: u8 = 2;
const RING: u8 = 3;
const OUTLINE: u8 = 4;
const REACH_BALL: u8 = 5;
const SUMO_BALL: u8 = 6;
/// First of the six agent colours (`AGENT_COLOURS`, the HTML player's).
const AGENT: u8 = 7;
/// Dashes of an assignment line (agent to entity), the first at the agent, the last at the entity.
const ASSIGNMENT_DASHES: usize = 8;
/// Marks unchanged pixels of the delta frames; never drawn.
const TRANSPARENT: u8 = 13;

/// The global palette, 16 sRGB colours in index order.
fn palette() -> Vec<u8> {
    let mut p =
        vec![[0xfa, 0xfa, 0xf7], [0xd6, 0xd6, 0xcf], [0xc4, 0xc4, 0xbb], [0xcc, 0x44, 0x44], [0x2a, 0x2a, 0x2a]];
    p.extend([REACH_BALL_COLOUR, SUMO_BALL_COLOUR]);
    p.extend(AGENT_COLOURS);
    p.extend([[0xff, 0x00, 0xff], [0, 0, 0], [0, 0, 0]]);
    debug_assert_eq!(p.len(), 16);
    p.concat()
}

/// Camera yaw about the vertical (rad; the HTML player's initial view) and pitch (45 degrees down).
const YAW: f64 = 0.6;
const PITCH: f64 = std::f64::consts::FRAC_PI_4;
/// Fraction of the image the episode's bounding box fills (the rest is margin).
const FILL: f64 = 0.92;

/// A fixed perspective camera on a sphere about `centre`, aimed at it.
struct Camera {
    centre: [f64; 3],
    /// Distance from the centre (m).
    dist: f64,
    /// Focal length in pixels.
    focal: f64,
    /// Projected centre of the bounding box at unit focal length, drawn at the image centre.
    mid: [f64; 2],
    /// Image centre in pixels.
    half: [f64; 2],
}

impl Camera {
    /// The camera that shows the box `lo`..`hi` (world, m) whole in a `width` x `height` image.
    fn fit(lo: [f64; 3], hi: [f64; 3], width: f64, height: f64) -> Camera {
        let centre = [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0);
        let radius = (0..3).map(|k| (hi[k] - lo[k]) / 2.0).map(|h| h * h).sum::<f64>().sqrt();
        let mut cam = Camera { centre, dist: 3.0 * radius, focal: 1.0, mid: [0.0; 2], half: [0.0; 2] };
        let (mut u, mut v) = ([f64::INFINITY, f64::NEG_INFINITY], [f64::INFINITY, f64::NEG_INFINITY]);
        for c in 0..8 {
            let p = [0, 1, 2].map(|k| if c >> k & 1 == 0 { lo[k] } else { hi[k] });
            let [x, _, z, depth] = cam.view(p);
            u = [u[0].min(x / depth), u[1].max(x / depth)];
            v = [v[0].min(z / depth), v[1].max(z / depth)];
        }
        cam.focal = FILL * (width / (u[1] - u[0])).min(height / (v[1] - v[0]));
        cam.mid = [(u[0] + u[1]) / 2.0, (v[0] + v[1]) / 2.0];
        cam.half = [width / 2.0, height / 2.0];
        cam
    }

    /// Camera coordinates of `p`: x right, y towards the camera, z up (relative to the
    /// centre), and the depth along the view axis (as the HTML player's `project`).
    fn view(&self, p: [f64; 3]) -> [f64; 4] {
        let [dx, dy, dz] = [0, 1, 2].map(|k| p[k] - self.centre[k]);
        let (sy, cy, sp, cp) = (YAW.sin(), YAW.cos(), PITCH.sin(), PITCH.cos());
        let (x, y0) = (cy * dx + sy * dy, -sy * dx + cy * dy);
        let (y, z) = (cp * y0 + sp * dz, -sp * y0 + cp * dz);
        [x, y, z, self.dist - y]
    }

    /// Pixel position of `p`, its depth (m) and the pixels per metre there.
    fn project(&self, p: [f64; 3]) -> ([f64; 2], f64, f64) {
        let [x, _, z, depth] = self.view(p);
        let s = self.focal / depth;
        let px = [
            self.half[0] + (x / depth - self.mid[0]) * self.focal,
            self.half[1] - (z / depth - self.mid[1]) * self.focal,
        ];
        (px, depth, s)
    }

    /// A ground-plane line from `a` to `b` (z = 0) at `radius` pixels, cut where it comes
    /// nearer than a tenth of the camera distance (the grid reaches past the framed box).
    fn ground_line(&self, canvas: &mut Canvas, a: [f64; 2], b: [f64; 2], radius: f64, colour: u8) {
        let near = 0.1 * self.dist;
        let (pa, pb) = ([a[0], a[1], 0.0], [b[0], b[1], 0.0]);
        let (da, db) = (self.view(pa)[3], self.view(pb)[3]);
        if da < near && db < near {
            return;
        }
        let cut = |from: [f64; 3], to: [f64; 3], df: f64, dt: f64| {
            let t = (near - df) / (dt - df);
            [0, 1, 2].map(|k| from[k] + t * (to[k] - from[k]))
        };
        let pa2 = if da < near { cut(pa, pb, da, db) } else { pa };
        let pb2 = if db < near { cut(pb, pa, db, da) } else { pb };
        canvas.capsule(self.project(pa2).0, self.project(pb2).0, radius, colour);
    }
}

/// One thing to draw in painter's order: a capsule (`a` != `b`) or a disc, in pixels.
struct Prim {
    depth: f64,
    a: [f64; 2],
    b: [f64; 2],
    radius: f64,
    colour: u8,
}

impl Trajectory {
    /// The episode as an animated GIF (module docs of `render`: a fixed camera framing the
    /// whole episode, agents by team or agent colour, balls, ground grid, Sumo's arena ring),
    /// one GIF frame per `options.frame_step` recorded frames, looping forever.
    ///
    /// A zero `width`, `height`, `frame_step` or `delay_cs`, or an empty trajectory, is a
    /// [`TaskError::BadArgument`] naming it.
    pub fn to_gif(&self, options: &GifOptions) -> Result<Vec<u8>, TaskError> {
        let bad = |what: &str, value: String, message: &str| {
            Err(TaskError::BadArgument { what: what.into(), value, message: message.into() })
        };
        for (what, value) in [
            ("width", options.width as usize),
            ("height", options.height as usize),
            ("frame_step", options.frame_step),
            ("delay_cs", options.delay_cs as usize),
        ] {
            if value == 0 {
                return bad(what, "0".into(), "must be at least 1");
            }
        }
        if self.is_empty() {
            return bad("trajectory", "0 frames".into(), "a GIF needs at least one recorded frame");
        }
        let (w, h) = (options.width as usize, options.height as usize);
        let geoms = self.agent_geoms();
        let sumo = self.scene.kind() == TaskKind::Sumo;
        // The arena ring: about the centre ball (fixed for the episode), Sumo only.
        let ring = self.balls[0].first().filter(|_| sumo).map(|c| (*c, self.scene.spec.radius));

        // Bounding box of everything drawn in any frame (and the ground), at least 1 m a side.
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let mut grow = |p: [f64; 3], r: f64| {
            if p.iter().all(|v| v.is_finite()) {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k] - r);
                    hi[k] = hi[k].max(p[k] + r);
                }
            }
        };
        for (bodies, balls) in self.bodies.iter().zip(&self.balls) {
            for g in &geoms {
                let (a, b) = self.segment(g.geom, bodies);
                grow(a, g.radius);
                grow(b, g.radius);
            }
            for c in balls {
                grow([c[0], c[1], BALL_RADIUS], BALL_RADIUS);
            }
        }
        if let Some((c, r)) = ring {
            grow([c[0] - r, c[1] - r, 0.0], 0.0);
            grow([c[0] + r, c[1] + r, 0.0], 0.0);
        }
        grow([0.0; 3], 0.0);
        for k in 0..3 {
            let (mid, half) = ((lo[k] + hi[k]) / 2.0, ((hi[k] - lo[k]) / 2.0).max(0.5));
            (lo[k], hi[k]) = (mid - half, mid + half);
        }
        let cam = Camera::fit(lo, hi, w as f64, h as f64);

        // The static background: ground grid (1 m, reaching one box size past the box) and ring.
        let mut background = Canvas::new(w, h, BACKGROUND);
        let reach = (0..2).map(|k| hi[k] - lo[k]).fold(2.0, f64::max);
        let (x0, x1) = ((lo[0] - reach).floor(), (hi[0] + reach).ceil());
        let (y0, y1) = ((lo[1] - reach).floor(), (hi[1] + reach).ceil());
        for x in (x0 as i64)..=(x1 as i64) {
            cam.ground_line(&mut background, [x as f64, y0], [x as f64, y1], 0.6, GRID);
        }
        for y in (y0 as i64)..=(y1 as i64) {
            cam.ground_line(&mut background, [x0, y as f64], [x1, y as f64], 0.6, GRID);
        }
        if let Some((c, r)) = ring {
            let at = |k: usize| {
                let t = k as f64 / 96.0 * std::f64::consts::TAU;
                cam.project([c[0] + r * t.cos(), c[1] + r * t.sin(), 0.0]).0
            };
            for k in 0..96 {
                background.capsule(at(k), at(k + 1), 1.1, RING);
            }
        }

        let ball = if sumo { SUMO_BALL } else { REACH_BALL };
        let mut encoder = gif::Encoder::new(Vec::new(), options.width, options.height, &palette())
            .and_then(|mut e| e.set_repeat(gif::Repeat::Infinite).map(|()| e))
            .map_err(|e| encoding_error(options, e))?;
        let mut previous: Option<Vec<u8>> = None;
        let mut prims = Vec::new();
        for (f, (bodies, balls)) in self.bodies.iter().zip(&self.balls).enumerate().step_by(options.frame_step) {
            let mut canvas = background.clone();
            prims.clear();
            for g in &geoms {
                let (a, b) = self.segment(g.geom, bodies);
                let ((pa, da, sa), (pb, db, sb)) = (cam.project(a), cam.project(b));
                let ppm = (sa + sb) / 2.0;
                // Blob shadow straight below, then the geom itself in painter's order.
                let shadow = |p: [f64; 3]| cam.project([p[0], p[1], 0.0]).0;
                canvas.capsule(shadow(a), shadow(b), (g.radius * ppm).max(1.0), SHADOW);
                let colour = AGENT + g.colour as u8;
                prims.push(Prim { depth: (da + db) / 2.0, a: pa, b: pb, radius: (g.radius * ppm).max(1.0), colour });
            }
            for c in balls {
                let (p, depth, s) = cam.project([c[0], c[1], BALL_RADIUS]);
                prims.push(Prim { depth, a: p, b: p, radius: (BALL_RADIUS * s).max(1.5), colour: ball });
            }
            // Far to near; the stable sort keeps model order between equal depths.
            prims.sort_by(|p, q| q.depth.total_cmp(&p.depth));
            for p in &prims {
                canvas.capsule(p.a, p.b, p.radius + 1.0, OUTLINE);
                canvas.capsule(p.a, p.b, p.radius, p.colour);
            }
            // The task assignment, on top: a dashed line in each assigned agent's colour
            // from its root body to its entity (the HTML player's marks).
            // The segment is cut into `2 ASSIGNMENT_DASHES - 1` pieces, every other one drawn.
            let pieces = (2 * ASSIGNMENT_DASHES - 1) as f64;
            for (a, e) in self.assignment_links(f) {
                let (from, to) = (self.entity_position(f, a), self.entity_position(f, e));
                let at = |t: f64| cam.project([0, 1, 2].map(|k| from[k] + t * (to[k] - from[k]))).0;
                let colour = AGENT + self.agent_colour(a) as u8;
                for k in (0..2 * ASSIGNMENT_DASHES).step_by(2) {
                    canvas.capsule(at(k as f64 / pieces), at((k + 1) as f64 / pieces), 1.0, colour);
                }
            }
            let frame = match &previous {
                None => full_frame(options, &canvas.pixels),
                Some(prev) => delta_frame(options, prev, &canvas.pixels),
            };
            encoder.write_frame(&frame).map_err(|e| encoding_error(options, e))?;
            previous = Some(canvas.pixels);
        }
        encoder.into_inner().map_err(|e| encoding_error(options, e))
    }
}

/// The whole image as one frame.
fn full_frame<'a>(options: &GifOptions, pixels: &'a [u8]) -> gif::Frame<'a> {
    gif::Frame {
        width: options.width,
        height: options.height,
        delay: options.delay_cs,
        dispose: gif::DisposalMethod::Keep,
        buffer: Cow::Borrowed(pixels),
        ..gif::Frame::default()
    }
}

/// The smallest rectangle in which `pixels` differ from `previous`, drawn over the kept
/// previous frame with unchanged pixels transparent (1 x 1 and transparent when nothing changed).
fn delta_frame(options: &GifOptions, previous: &[u8], pixels: &[u8]) -> gif::Frame<'static> {
    let w = options.width as usize;
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for (i, (p, q)) in previous.iter().zip(pixels).enumerate() {
        if p != q {
            let (x, y) = (i % w, i / w);
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
    }
    let (left, top, width, height, buffer) = if x0 > x1 {
        (0, 0, 1, 1, vec![TRANSPARENT])
    } else {
        let mut buffer = Vec::with_capacity((x1 - x0 + 1) * (y1 - y0 + 1));
        for y in y0..=y1 {
            let row = y * w + x0..y * w + x1 + 1;
            buffer.extend(
                previous[row.clone()].iter().zip(&pixels[row]).map(|(p, q)| if p == q { TRANSPARENT } else { *q }),
            );
        }
        // The rectangle lies inside the image, whose sides fit in u16.
        (x0 as u16, y0 as u16, (x1 - x0 + 1) as u16, (y1 - y0 + 1) as u16, buffer)
    };
    gif::Frame {
        left,
        top,
        width,
        height,
        delay: options.delay_cs,
        dispose: gif::DisposalMethod::Keep,
        transparent: Some(TRANSPARENT),
        buffer: Cow::Owned(buffer),
        ..gif::Frame::default()
    }
}

/// The encoder's failure (writing to memory with a valid palette and frames: not expected).
fn encoding_error(options: &GifOptions, e: gif::EncodingError) -> TaskError {
    TaskError::BadArgument {
        what: "gif".into(),
        value: format!("{}x{}", options.width, options.height),
        message: format!("the GIF encoder failed: {e}"),
    }
}
