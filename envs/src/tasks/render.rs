//! Saving an episode and looking at it: a [`Trajectory`] holds every body's world pose and
//! the balls at each control step; it is written as CSV ([`Trajectory::to_csv`]), as a
//! self-contained HTML page ([`Trajectory::to_html`]) that plays it back on a canvas with no
//! network access (capsules and spheres under a simple perspective camera, play/pause, a
//! step slider, drag to turn the camera, wheel to zoom; the red circle is the Sumo arena
//! about the centre ball or the Reach placement disc about the origin; a dashed line in an
//! agent's colour joins it to the entity its policy's task assignment gave it at that step,
//! [`Trajectory::set_assignments`], named under the player), or as an animated
//! GIF ([`Trajectory::to_gif`] with [`GifOptions`]: the same scene under a fixed camera,
//! drawn by a small software rasterizer, `render/gif_writer.rs` and `render/raster.rs`).
//!
//! ```no_run
//! use envs::tasks::render::record_episode;
//! let traj = record_episode("team_reach/1_ant", 3, 200, |_obs, actions| actions.fill(0.5)).unwrap();
//! std::fs::write("episode.html", traj.to_html()).unwrap();
//! let gif = traj.to_gif(&envs::tasks::render::GifOptions::default()).unwrap();
//! std::fs::write("episode.gif", gif).unwrap();
//! ```

mod gif_writer;
mod raster;

pub use gif_writer::GifOptions;

use super::error::TaskError;
use super::eval_modes::StartMode;
use super::scene::{BALL_RADIUS, Scene};
use super::spec::TaskKind;
use super::vec_env::VecEnv;
use crate::data::Data;
use crate::layout::Observation;
use crate::math::{add, mat_vec, quat_to_mat, sub};
use crate::model::Shape;
use std::fmt::Write;

/// Body poses and balls of one environment over an episode.
#[derive(Clone, Debug)]
pub struct Trajectory {
    /// Environment name.
    pub name: String,
    /// The scene (geoms, agents).
    pub scene: Scene,
    /// Seconds between frames (the control step).
    pub dt: f64,
    /// Per frame, the world pose `(position, quaternion w x y z)` of every model body.
    pub bodies: Vec<Vec<([f64; 3], [f64; 4])>>,
    /// Per frame, the ball centres (x, y).
    pub balls: Vec<Vec<[f64; 2]>>,
    /// Per control step, the entity each agent was assigned to by the task assignment of
    /// the policy that chose the step's action: a scene entity index (the agents `0..A`,
    /// then the balls `A..A+M`), `None` for an agent without one. Step `k` acts on frame
    /// `k`, and the player shows the last step's on the final frame. Empty when no policy
    /// with a task assignment played ([`Trajectory::set_assignments`]).
    pub assigned: Vec<Vec<Option<usize>>>,
}

impl Trajectory {
    /// An empty trajectory of `scene`.
    pub fn new(scene: &Scene) -> Trajectory {
        let dt = scene.model.opt.timestep * scene.spec.physics_steps as f64;
        Trajectory {
            name: scene.spec.name.clone(),
            scene: scene.clone(),
            dt,
            bodies: Vec::new(),
            balls: Vec::new(),
            assigned: Vec::new(),
        }
    }

    /// Records the task assignment of every control step ([`Trajectory::assigned`]): one
    /// row per step, at most one per frame, each with an entry per agent naming an entity
    /// of the scene other than the agent itself.
    pub fn set_assignments(&mut self, per_step: Vec<Vec<Option<usize>>>) -> Result<(), TaskError> {
        let (na, ne) = (self.scene.n_agents(), self.scene.n_agents() + self.scene.spec.balls);
        let bad =
            |value: String, message: String| TaskError::BadSpec { what: "task assignment".into(), value, message };
        if per_step.len() > self.len() {
            return Err(bad(
                format!("{} steps", per_step.len()),
                format!("more steps than the trajectory's {} frames", self.len()),
            ));
        }
        for (k, row) in per_step.iter().enumerate() {
            if row.len() != na {
                return Err(bad(format!("step {k}: {} entries", row.len()), format!("the scene has {na} agents")));
            }
            for (a, e) in row.iter().enumerate() {
                if let Some(e) = *e
                    && (e >= ne || e == a)
                {
                    return Err(bad(
                        format!("step {k}: agent {a} -> entity {e}"),
                        format!("an entity of the scene ({ne}) other than the agent itself"),
                    ));
                }
            }
        }
        self.assigned = per_step;
        Ok(())
    }

    /// The world position of entity `e` at frame `f`: an agent's root body, or a ball's
    /// centre.
    fn entity_position(&self, f: usize, e: usize) -> [f64; 3] {
        let na = self.scene.n_agents();
        match self.scene.agents.get(e) {
            Some(agent) => self.bodies[f][agent.root_body].0,
            None => {
                let b = self.balls[f][e - na];
                [b[0], b[1], BALL_RADIUS]
            }
        }
    }

    /// The task assignment shown at frame `f`: `(agent, entity)` per assigned agent (the
    /// record of the step that frame starts, the last one for the final frame; none when
    /// nothing was recorded).
    fn assignment_links(&self, f: usize) -> Vec<(usize, usize)> {
        let Some(row) = self.assigned.get(f.min(self.assigned.len().saturating_sub(1))) else {
            return Vec::new();
        };
        row.iter().enumerate().filter_map(|(a, e)| e.map(|e| (a, e))).collect()
    }

    /// The player's assignment marks of frame `f`: `[agent, from xyz, to xyz]` per assigned
    /// agent (from its root body to the entity), and the caption naming each pair.
    fn assignment_marks(&self, f: usize) -> (Vec<f64>, String) {
        let na = self.scene.n_agents();
        let (mut marks, mut caption) = (Vec::new(), Vec::new());
        for (a, e) in self.assignment_links(f) {
            marks.push(a as f64);
            marks.extend(self.entity_position(f, a));
            marks.extend(self.entity_position(f, e));
            let to = if e < na { format!("agent {e}") } else { format!("ball {}", e - na) };
            caption.push(format!("agent {a} → {to}"));
        }
        (marks, caption.join(", "))
    }

    /// Appends a frame: the body poses of `data` (its kinematics must be current, as after
    /// any [`VecEnv`] step) and the balls.
    pub fn record(&mut self, data: &Data, balls: &[[f64; 2]]) {
        self.bodies.push(data.xpos.iter().zip(&data.xquat).map(|(p, q)| (*p, *q)).collect());
        self.balls.push(balls.to_vec());
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.bodies.len()
    }

    /// Whether there are no frames.
    pub fn is_empty(&self) -> bool {
        self.bodies.is_empty()
    }

    /// CSV: `frame,kind,index,x,y,z,qw,qx,qy,qz` with `kind` `body` (model body index,
    /// world pose) or `ball` (centre, identity orientation).
    pub fn to_csv(&self) -> String {
        let mut s = String::from("frame,kind,index,x,y,z,qw,qx,qy,qz\n");
        for (f, (bodies, balls)) in self.bodies.iter().zip(&self.balls).enumerate() {
            for (i, (p, q)) in bodies.iter().enumerate().skip(1) {
                let _ = writeln!(s, "{f},body,{i},{},{},{},{},{},{},{}", p[0], p[1], p[2], q[0], q[1], q[2], q[3]);
            }
            for (i, b) in balls.iter().enumerate() {
                let _ = writeln!(s, "{f},ball,{i},{},{},{BALL_RADIUS},1,0,0,0", b[0], b[1]);
            }
        }
        s
    }

    /// The self-contained HTML player (module docs).
    pub fn to_html(&self) -> String {
        // Primitives: every agent geom (sphere or capsule), then the balls.
        let geoms = self.agent_geoms();
        let kinds: Vec<u8> = geoms.iter().map(|g| u8::from(!g.sphere)).collect();
        let radii: Vec<f64> = geoms.iter().map(|g| g.radius).collect();
        let hex = |[r, g, b]: [u8; 3]| format!("#{r:02x}{g:02x}{b:02x}");
        let colours: Vec<String> = geoms.iter().map(|g| hex(AGENT_COLOURS[g.colour])).collect();
        let ball_colour = hex(if self.scene.n_teams() == 2 { SUMO_BALL_COLOUR } else { REACH_BALL_COLOUR });
        let mut frames = String::from("[");
        for (f, (bodies, balls)) in self.bodies.iter().zip(&self.balls).enumerate() {
            frames.push_str(if f == 0 { "[" } else { ",\n[" });
            let mut first = true;
            let mut num = |s: &mut String, x: f64| {
                if !first {
                    s.push(',');
                }
                first = false;
                let _ = write!(s, "{}", millimetres(x));
            };
            for g in &geoms {
                let (a, b) = self.segment(g.geom, bodies);
                for x in a.into_iter().chain(b) {
                    num(&mut frames, x);
                }
            }
            for b in balls {
                num(&mut frames, b[0]);
                num(&mut frames, b[1]);
            }
            frames.push(']');
        }
        frames.push(']');
        // The task assignment's marks, per frame (empty arrays when none was recorded).
        let (mut marks, mut captions) = (String::from("["), String::from("["));
        for f in 0..self.len() {
            let (m, c) = self.assignment_marks(f);
            let sep = if f == 0 { "" } else { "," };
            let m: Vec<String> = m.iter().map(|&x| millimetres(x).to_string()).collect();
            let _ = write!(marks, "{sep}[{}]", m.join(","));
            let _ = write!(captions, "{sep}\"{c}\"");
        }
        marks.push(']');
        captions.push(']');
        let list = |v: Vec<String>| v.join(",");
        let data = format!(
            "{{\"name\":{:?},\"sumo\":{},\"dt\":{},\"radius\":{},\"ball\":{BALL_RADIUS},\"ballColour\":{ball_colour:?},\
             \"kinds\":[{}],\"radii\":[{}],\"colours\":[{}],\"agentColours\":[{}],\"marks\":{marks},\"captions\":{captions},\
             \"frames\":{frames}}}",
            self.name,
            self.scene.kind() == TaskKind::Sumo,
            self.dt,
            self.scene.spec.radius,
            list(kinds.iter().map(|k| k.to_string()).collect()),
            list(radii.iter().map(|r| r.to_string()).collect()),
            list(colours.iter().map(|c| format!("{c:?}")).collect()),
            list(
                (0..self.scene.n_agents()).map(|a| format!("{:?}", hex(AGENT_COLOURS[self.agent_colour(a)]))).collect()
            ),
        );
        format!("{HTML_HEAD}<script>\nconst D = {data};\n{PLAYER_JS}</script>\n</body>\n</html>\n")
    }

    /// The drawn agent geoms (spheres and capsules of bodies that belong to an agent), in
    /// model order, with their colour slots: by team when there are two teams, else by agent.
    fn agent_geoms(&self) -> Vec<AgentGeom> {
        let m = &self.scene.model;
        let agent_of = |body: usize| self.scene.agents.iter().position(|a| a.bodies.contains(&body));
        let mut out = Vec::new();
        for (g, geom) in m.geoms.iter().enumerate() {
            let Some(a) = agent_of(geom.body) else { continue };
            let colour = self.agent_colour(a);
            let (sphere, radius) = match geom.shape {
                Shape::Sphere { radius } => (true, radius),
                Shape::Capsule { radius, .. } => (false, radius),
                Shape::Plane => (true, 0.0),
            };
            out.push(AgentGeom { geom: g, colour, sphere, radius });
        }
        out
    }

    /// Agent `a`'s colour slot in [`AGENT_COLOURS`]: its team's when there are two teams,
    /// else its own (cycled).
    fn agent_colour(&self, a: usize) -> usize {
        let slot = if self.scene.n_teams() == 2 { self.scene.agents[a].team } else { a };
        slot % AGENT_COLOURS.len()
    }

    /// The world-frame axis of geom `g` in a frame's body poses: the end points of a
    /// capsule's segment, or the centre twice for a sphere.
    fn segment(&self, g: usize, bodies: &[([f64; 3], [f64; 4])]) -> ([f64; 3], [f64; 3]) {
        let geom = &self.scene.model.geoms[g];
        let (p, q) = bodies[geom.body];
        let r = quat_to_mat(q);
        let c = add(p, mat_vec(&r, geom.pos));
        let half = match geom.shape {
            Shape::Capsule { half_length, .. } => half_length,
            _ => 0.0,
        };
        let axis = mat_vec(&r, mat_vec(&geom.mat, [0.0, 0.0, half]));
        (sub(c, axis), add(c, axis))
    }
}

/// One drawn agent geom (see `Trajectory::agent_geoms`).
struct AgentGeom {
    /// Model geom index.
    geom: usize,
    /// Index into [`AGENT_COLOURS`].
    colour: usize,
    /// Sphere (drawn as a disc) or capsule (a thick segment).
    sphere: bool,
    /// Radius (m).
    radius: f64,
}

/// Agent colours (sRGB), one per team in Sumo, one per agent in Reach (cycled).
const AGENT_COLOURS: [[u8; 3]; 6] = [
    [0x3b, 0x7d, 0xd8],
    [0xe0, 0x7b, 0x39],
    [0x4a, 0xa5, 0x64],
    [0xb0, 0x4f, 0xc0],
    [0xc9, 0xa2, 0x27],
    [0xd9, 0x4f, 0x5c],
];
/// Reach's goal balls.
const REACH_BALL_COLOUR: [u8; 3] = [0xe8, 0xc5, 0x47];
/// Sumo's centre ball.
const SUMO_BALL_COLOUR: [u8; 3] = [0x88, 0x88, 0x88];

/// `x` rounded to three decimals (millimetres, for the player's coordinates).
fn millimetres(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Plays `steps` control steps (or until the episode ends) of one environment of `name`
/// with the fixed start of `seed`, asking `policy(observation, actions)` for each action
/// row, and records every frame (the start and the state after each step).
pub fn record_episode(
    name: &str,
    seed: u64,
    steps: usize,
    mut policy: impl FnMut(&Observation, &mut [f32]),
) -> Result<Trajectory, TaskError> {
    let mut env = VecEnv::from_name(name, 1, seed, StartMode::fixed(seed))?;
    env.set_auto_reset(false);
    let mut traj = Trajectory::new(env.scene());
    let mut actions = vec![0.0f32; env.n_actions()];
    let frame = |env: &VecEnv, traj: &mut Trajectory| {
        if let (Some(d), Some(b)) = (env.data(0), env.balls(0)) {
            traj.record(d, b);
        }
    };
    frame(&env, &mut traj);
    for _ in 0..steps {
        policy(env.obs(), &mut actions);
        let out = env.step(&actions)?;
        let ended = out.terminated[0] || out.truncated[0];
        frame(&env, &mut traj);
        if ended {
            break;
        }
    }
    Ok(traj)
}

const HTML_HEAD: &str = r#"<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>MeBen episode</title>
<style>
body { font-family: sans-serif; margin: 8px; background: #f4f4f0; }
canvas { background: #ffffff; border: 1px solid #bbb; display: block; }
#bar { margin-top: 6px; display: flex; gap: 8px; align-items: center; }
#step { width: 520px; }
</style>
</head>
<body>
<div id="title"></div>
<canvas id="c" width="800" height="560"></canvas>
<div id="bar"><button id="play">pause</button><input id="step" type="range" min="0" value="0"><span id="info"></span></div>
<div id="assigned"></div>
"#;

const PLAYER_JS: &str = r#"
const cv = document.getElementById('c'), g = cv.getContext('2d');
const slider = document.getElementById('step'), info = document.getElementById('info');
const btn = document.getElementById('play'), assigned = document.getElementById('assigned');
document.getElementById('title').textContent = D.name + '  (drag: turn, wheel: zoom)';
slider.max = D.frames.length - 1;
let frame = 0, playing = true, yaw = 0.6, pitch = 0.55, dist = 3 * D.radius + 4;
function centre(f) {
  // Sumo: the centre ball (the arena's centre); Reach: the origin (the placement disc's).
  const F = D.frames[f], o = 6 * D.kinds.length;
  return D.sumo && F.length > o ? [F[o], F[o + 1], 0] : [0, 0, 0];
}
function project(p, c) {
  // Camera on a sphere around c; returns [screen x, screen y, depth, pixels per metre].
  const dx = p[0] - c[0], dy = p[1] - c[1], dz = p[2] - c[2];
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const x = cy * dx + sy * dy, y0 = -sy * dx + cy * dy;
  const y = cp * y0 + sp * dz, z = -sp * y0 + cp * dz;
  const depth = dist - y, s = 700 / Math.max(depth, 0.1);
  return [cv.width / 2 + x * s, cv.height * 0.55 - z * s, depth, s];
}
function draw() {
  const F = D.frames[frame], c = centre(frame);
  g.clearRect(0, 0, cv.width, cv.height);
  g.strokeStyle = '#ccc'; g.lineWidth = 1;
  for (let k = -10; k <= 10; k++) {
    const a = project([c[0] + k, c[1] - 10, 0], c), b = project([c[0] + k, c[1] + 10, 0], c);
    const e = project([c[0] - 10, c[1] + k, 0], c), f = project([c[0] + 10, c[1] + k, 0], c);
    g.beginPath(); g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]); g.moveTo(e[0], e[1]); g.lineTo(f[0], f[1]); g.stroke();
  }
  g.strokeStyle = '#c44'; g.lineWidth = 2; g.beginPath();
  for (let k = 0; k <= 64; k++) {
    const t = k / 64 * 2 * Math.PI, p = project([c[0] + D.radius * Math.cos(t), c[1] + D.radius * Math.sin(t), 0], c);
    if (k) g.lineTo(p[0], p[1]); else g.moveTo(p[0], p[1]);
  }
  g.stroke();
  const prims = [];
  for (let i = 0; i < D.kinds.length; i++) {
    const a = project(F.slice(6 * i, 6 * i + 3), c), b = project(F.slice(6 * i + 3, 6 * i + 6), c);
    prims.push([(a[2] + b[2]) / 2, a, b, D.radii[i], D.colours[i]]);
  }
  for (let i = 6 * D.kinds.length; i < F.length; i += 2) {
    const a = project([F[i], F[i + 1], D.ball], c);
    prims.push([a[2], a, a, D.ball, D.ballColour]);
  }
  prims.sort((p, q) => q[0] - p[0]);
  g.lineCap = 'round';
  for (const [, a, b, r, col] of prims) {
    g.strokeStyle = col; g.fillStyle = col;
    if (a === b || (Math.abs(a[0] - b[0]) < 0.5 && Math.abs(a[1] - b[1]) < 0.5)) {
      g.beginPath(); g.arc(a[0], a[1], Math.max(r * a[3], 1), 0, 2 * Math.PI); g.fill();
    } else {
      g.lineWidth = Math.max(2 * r * (a[3] + b[3]) / 2, 1);
      g.beginPath(); g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]); g.stroke();
    }
  }
  // The task assignment: a dashed line in the agent's colour from its root to its entity.
  const M = D.marks[frame];
  g.setLineDash([6, 4]); g.lineWidth = 2;
  for (let i = 0; i + 7 <= M.length; i += 7) {
    const a = project(M.slice(i + 1, i + 4), c), b = project(M.slice(i + 4, i + 7), c);
    g.strokeStyle = D.agentColours[M[i]];
    g.beginPath(); g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]); g.stroke();
  }
  g.setLineDash([]);
  assigned.textContent = D.captions[frame] ? 'assigned: ' + D.captions[frame] : '';
  slider.value = frame;
  info.textContent = 'step ' + frame + ' / ' + (D.frames.length - 1) + '   t = ' + (frame * D.dt).toFixed(2) + ' s';
}
btn.onclick = () => { playing = !playing; btn.textContent = playing ? 'pause' : 'play'; };
slider.oninput = () => { frame = +slider.value; draw(); };
let drag = null;
cv.onmousedown = e => { drag = [e.clientX, e.clientY]; };
window.onmouseup = () => { drag = null; };
cv.onmousemove = e => {
  if (!drag) return;
  yaw += (e.clientX - drag[0]) * 0.01;
  pitch = Math.min(1.5, Math.max(0.05, pitch + (e.clientY - drag[1]) * 0.01));
  drag = [e.clientX, e.clientY]; draw();
};
cv.onwheel = e => { e.preventDefault(); dist = Math.max(2, dist * (e.deltaY > 0 ? 1.1 : 0.9)); draw(); };
setInterval(() => { if (playing) { frame = (frame + 1) % D.frames.length; draw(); } }, 1000 * D.dt);
draw();
"#;
