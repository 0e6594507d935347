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
