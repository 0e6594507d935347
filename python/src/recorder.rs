//! `env.render(path)`: the episode of environment 0, recorded frame by frame while the
//! environment steps (only when asked for at `make`), written as the HTML player, a GIF or
//! CSV by the Rust renderer.

use envs::tasks::VecEnv;
use envs::tasks::render::{GifOptions, Trajectory};
use pyo3::PyResult;
use pyo3::exceptions::PyOSError;

use crate::errors::{bad_argument, task_error};

/// Frames of environment 0's current episode, and of the one that ended last.
pub struct Recorder {
    current: Trajectory,
    ended: Option<Trajectory>,
}

impl Recorder {
    /// Starts recording at the current state of environment 0.
    pub fn new(env: &VecEnv) -> Recorder {
        let mut r = Recorder { current: Trajectory::new(env.scene()), ended: None };
        r.frame(env);
        r
    }

    fn frame(&mut self, env: &VecEnv) {
        if let (Some(d), Some(b)) = (env.data(0), env.balls(0)) {
            self.current.record(d, b);
        }
    }

    /// Every environment began a new episode.
    pub fn restart(&mut self, env: &VecEnv) {
        *self = Recorder::new(env);
    }

    /// After a step: records the new frame; when environment 0's episode ended and it began
    /// the next one (auto-reset), the ended episode is kept (without its last frame, which the
    /// reset replaced) and a new recording starts.
    pub fn after_step(&mut self, env: &VecEnv, ended: bool, auto_reset: bool) {
        if ended && auto_reset {
            let done = std::mem::replace(&mut self.current, Trajectory::new(env.scene()));
            self.ended = Some(done);
        }
        self.frame(env);
    }

    /// Writes the recorded episode to `path` (`.html`, `.gif` or `.csv`): the current one, or
    /// the one that just ended when the current one has no step yet.
    pub fn write(&self, path: &str) -> PyResult<usize> {
        let traj = match &self.ended {
            Some(e) if self.current.len() <= 1 => e,
            _ => &self.current,
        };
        let ext = std::path::Path::new(path).extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let bytes = match ext.as_str() {
            "html" => traj.to_html().into_bytes(),
            "gif" => traj.to_gif(&GifOptions::default()).map_err(task_error)?,
            "csv" => traj.to_csv().into_bytes(),
            _ => {
                return Err(bad_argument(
                    "path",
                    format!("{path:?}"),
                    "expected a file name ending in .html, .gif or .csv",
                ));
            }
        };
        std::fs::write(path, bytes).map_err(|e| PyOSError::new_err(format!("{path}: cannot write: {e}")))?;
        Ok(traj.len())
    }
}
