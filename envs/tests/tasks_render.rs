//! Trajectories: recording an episode, the CSV and the self-contained HTML player.

use envs::tasks::render::record_episode;

#[test]
fn an_episode_records_every_frame_and_renders_offline() {
    let traj = record_episode("team_sumo/2_ants", 4, 30, |_obs, a| a.fill(0.3)).unwrap();
    assert_eq!(traj.len(), 31); // the start and 30 steps
    let nb = traj.scene.model.bodies.len() - 1;
    let csv = traj.to_csv();
    assert_eq!(csv.lines().count(), 1 + 31 * (nb + 1));
    assert!(csv.lines().nth(1).unwrap().starts_with("0,body,1,"));
    // The last frame is the state after the last step.
    let html = traj.to_html();
    assert!(html.starts_with("<!DOCTYPE html>") && html.contains("<canvas") && html.contains("const D = {"));
    assert!(!html.contains("http") && !html.contains("src="), "the page must not load anything");
    assert_eq!(html.matches("],\n[").count(), 30, "one array per frame");
    assert!(html.len() < 2_000_000);
    // Recording stops when the episode ends (here at the latest by the time limit).
    let ended = record_episode("team_sumo/2_ants", 4, 2000, |_obs, a| a.fill(1.0)).unwrap();
    assert!(ended.len() <= 1001, "recording went past the end of the episode");
    assert!(record_episode("team_sumo/9_ants", 0, 1, |_, _| {}).is_err());
}

/// Runs the page in headless Chromium when it is installed (skipped otherwise): the script
/// must run without errors and the animation advance.
#[test]
fn the_html_player_runs_in_headless_chromium() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let Some(browser) = ["chromium", "chromium-browser"]
        .into_iter()
        .find(|b| Command::new(b).arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok())
    else {
        eprintln!("skipped: no chromium in PATH");
        return;
    };
    let traj = record_episode("team_reach/2_ant_claw", 1, 40, |_obs, a| a.fill(-0.5)).unwrap();
    let dir = std::env::temp_dir().join(format!("meben_render_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let page = dir.join("episode.html");
    std::fs::write(&page, traj.to_html()).unwrap();
    let mut child = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"])
        .args(["--virtual-time-budget=1000", "--dump-dom", &format!("file://{}", page.display())])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("chromium did not finish within 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let dom = String::from_utf8_lossy(&out.stdout);
    let _ = std::fs::remove_dir_all(&dir);
    // The info line is written by the script: "step k / 40 ...", with k > 0 after 1 s.
    let info = dom.split("id=\"info\">").nth(1).and_then(|s| s.split('<').next()).unwrap_or("");
    let step: usize =
        info.strip_prefix("step ").and_then(|s| s.split(' ').next()).and_then(|s| s.parse().ok()).unwrap_or(0);
    assert!(info.contains("/ 40") && step > 0, "the player did not run: info line {info:?}");
}
