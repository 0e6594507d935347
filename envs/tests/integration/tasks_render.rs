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

/// The environment variable that makes a missing browser a failure instead of a skip;
/// `./test.sh` (what CI runs) installs Chromium and sets it.
const REQUIRE_BROWSER: &str = "MEBEN_REQUIRE_BROWSER";

/// Runs the page in headless Chromium: the script must run without errors and the animation
/// advance. Without Chromium the test is skipped, unless `MEBEN_REQUIRE_BROWSER=1` (set by
/// `./test.sh`), where a missing browser fails it.
#[test]
fn the_html_player_runs_in_headless_chromium() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let found = ["chromium", "chromium-browser"]
        .into_iter()
        .find(|b| Command::new(b).arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok());
    let Some(browser) = found else {
        let required = std::env::var(REQUIRE_BROWSER).is_ok_and(|v| v == "1");
        assert!(
            !required,
            "{REQUIRE_BROWSER}=1 but no chromium or chromium-browser in PATH (apt-get install chromium)"
        );
        eprintln!("skipped: no chromium in PATH (set {REQUIRE_BROWSER}=1 to make this a failure)");
        return;
    };
    let mut traj = record_episode("team_reach/2_ant_claw", 1, 40, |_obs, a| a.fill(-0.5)).unwrap();
    // Each agent marked with the other's ball at every step.
    let na = traj.scene.n_agents();
    assert_eq!(na, 2);
    traj.set_assignments(vec![vec![Some(na + 1), Some(na)]; 40]).unwrap();
    let dir = std::env::temp_dir().join(format!("meben_render_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let page = dir.join("episode.html");
    std::fs::write(&page, traj.to_html()).unwrap();
    // The DOM goes to a file, not a pipe: a page larger than the pipe's buffer would block
    // the browser while this test waits for it to exit.
    let (dom_path, log_path) = (dir.join("dom.html"), dir.join("chromium.log"));
    let mut child = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run"])
        .args(["--disable-background-networking", "--disable-component-update", "--disable-sync"])
        .arg(format!("--user-data-dir={}", dir.join("profile").display()))
        .args(["--virtual-time-budget=1000", "--dump-dom", &format!("file://{}", page.display())])
        .stdout(std::fs::File::create(&dom_path).unwrap())
        .stderr(std::fs::File::create(&log_path).unwrap())
        .stdin(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            let _ = child.wait();
            let log = std::fs::read_to_string(&log_path).unwrap_or_default();
            panic!("chromium did not finish within 60 s; its log:\n{log}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let dom = std::fs::read_to_string(&dom_path).unwrap_or_default();
    let log = std::fs::read_to_string(&log_path).unwrap_or_default();
    let _ = std::fs::remove_dir_all(&dir);
    // The info line is written by the script: "step k / 40 ...", with k > 0 after 1 s.
    let info = dom.split("id=\"info\">").nth(1).and_then(|s| s.split('<').next()).unwrap_or("");
    let step: usize =
        info.strip_prefix("step ").and_then(|s| s.split(' ').next()).and_then(|s| s.parse().ok()).unwrap_or(0);
    assert!(info.contains("/ 40") && step > 0, "the player did not run: info line {info:?}; chromium's log:\n{log}");
    // The caption of the task assignment is written by the script, for the frame shown.
    let caption = dom.split("id=\"assigned\">").nth(1).and_then(|s| s.split('<').next()).unwrap_or("");
    assert_eq!(caption, "assigned: agent 0 → ball 1, agent 1 → ball 0", "chromium's log:\n{log}");
}

#[test]
fn a_recorded_task_assignment_is_checked_and_drawn() {
    let mut traj = record_episode("team_reach/2_ants", 2, 5, |_obs, a| a.fill(0.1)).unwrap();
    assert!(traj.assigned.is_empty());
    let html = traj.to_html();
    assert!(html.contains("\"marks\":[[],[],[],[],[],[]]") && html.contains("\"captions\":[\"\",\""), "no marks");
    // Bad rows are refused, naming the step, agent and entity, and change nothing.
    let err = |rows: Vec<Vec<Option<usize>>>, traj: &mut envs::tasks::render::Trajectory| {
        traj.set_assignments(rows).unwrap_err().to_string()
    };
    assert!(err(vec![vec![None, None]; 7], &mut traj).contains("7 steps"));
    assert!(err(vec![vec![Some(2)]], &mut traj).contains("step 0: 1 entries"));
    assert!(err(vec![vec![None, Some(1)]], &mut traj).contains("agent 1 -> entity 1"));
    assert!(err(vec![vec![Some(4), None]], &mut traj).contains("agent 0 -> entity 4"));
    assert!(traj.assigned.is_empty());
    // Agent 0 to ball 1 (entity 3) and agent 1 to agent 0, for the 5 steps: the final frame
    // shows the last step's. A mark runs from the agent's root to the entity.
    traj.set_assignments(vec![vec![Some(3), Some(0)]; 5]).unwrap();
    let html = traj.to_html();
    assert_eq!(html.matches("\"agent 0 → ball 1, agent 1 → agent 0\"").count(), 6, "a caption per frame");
    let root = |f: usize, a: usize| traj.bodies[f][traj.scene.agents[a].root_body].0;
    let ball = traj.balls[5][1];
    let r = |x: f64| (x * 1000.0).round() / 1000.0;
    let last = format!(
        "[0,{},{},{},{},{},0.1,1,{},{},{},{},{},{}]]",
        r(root(5, 0)[0]),
        r(root(5, 0)[1]),
        r(root(5, 0)[2]),
        r(ball[0]),
        r(ball[1]),
        r(root(5, 1)[0]),
        r(root(5, 1)[1]),
        r(root(5, 1)[2]),
        r(root(5, 0)[0]),
        r(root(5, 0)[1]),
        r(root(5, 0)[2]),
    );
    assert!(html.contains(&last), "the final frame's marks {last} not in the page");
}
