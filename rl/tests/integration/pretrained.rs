//! The shipped pretrained policies (`policies/`, its manifest `policies/index.toml`): the
//! manifest lists exactly the policies [`SHIPPED`] names and the directory holds (no entry
//! without its file, no policy file without its entry), each file has the recorded SHA-256
//! and loads, and each evaluates on [`EPISODES`] episodes within [`margin`] of the figure
//! recorded on 1024.
//!
//! **Margin.** The recorded figure `p` comes from 1024 episodes, the check from
//! [`EPISODES`] others (another batch size draws other starts), so the two differ by
//! sampling alone with standard deviation `sqrt(p (1 - p) (1/256 + 1/1024))` (at most 0.035);
//! the check allows 4 of those plus 0.02 (0.02 to 0.16): a policy file of another run, an
//! untrained one or a broken loader lands far outside it (an untrained `shnn` reaches 0 to
//! 3% on Team Reach), and sampling alone fails it about once in 15,000 checks.

use rl::app::policy_file::{Manifest, load_policy, policies_dir};
use rl::{EvalRequest, evaluate};

/// The policies shipped now, as `<env>/<model>`: whoever adds a policy to `policies/` adds its
/// name here, so that an empty or shrunken manifest is a failure, never a silent pass.
const SHIPPED: &[&str] = &["team_reach/1_ant/shnn", "team_reach/2_ants/shnn"];

/// Episodes of each check.
const EPISODES: usize = 256;

/// The allowed distance between the check and the recorded figure `p` of `recorded`
/// episodes (module docs).
fn margin(p: f64, recorded: usize) -> f64 {
    4.0 * (p * (1.0 - p) * (1.0 / EPISODES as f64 + 1.0 / recorded as f64)).sqrt() + 0.02
}

#[test]
fn every_shipped_policy_is_listed_present_and_evaluates_to_its_recorded_figure() {
    let dir = policies_dir();
    let manifest = Manifest::load(&dir).unwrap();
    let mut listed: Vec<String> = manifest.policy.iter().map(|p| p.name()).collect();
    listed.sort();
    let mut expected: Vec<String> = SHIPPED.iter().map(|s| s.to_string()).collect();
    expected.sort();
    assert_eq!(listed, expected, "{}: the manifest's policies are not the SHIPPED ones of this test", dir.display());
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".safetensors"))
        .collect();
    files.sort();
    let mut named: Vec<String> = manifest.policy.iter().map(|p| p.file.clone()).collect();
    named.sort();
    assert_eq!(files, named, "{}: policy files without a manifest entry, or entries without a file", dir.display());
    eprintln!("{} shipped policies to check: {}", manifest.policy.len(), manifest.names());
    for p in &manifest.policy {
        let path = dir.join(&p.file);
        assert!(dir.join(&p.provenance).is_file(), "{}: no provenance file {}", p.name(), p.provenance);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            rl::mappo::checksum::sha256_hex(&bytes),
            p.sha256,
            "{}: the file is not the recorded one",
            path.display()
        );
        let f = load_policy(&path).unwrap();
        assert_eq!(
            (f.config.env.as_str(), f.config.model.as_str()),
            (p.env.as_str(), p.model.as_str()),
            "{}",
            p.name()
        );
        assert_eq!(f.config.opponent, p.opponent, "{}", p.name());
        let request = EvalRequest {
            episodes: EPISODES,
            seed: p.eval_seed,
            deterministic: Some(!p.sampled),
            fixed: false,
            rotation_deg: None,
            translation: None,
        };
        let e = evaluate(&f.config.env, &f.teams, &request.options(&f.config)).unwrap();
        let got = match p.metric.as_str() {
            "success_rate" => e.success_rate,
            "win_rate" => e.win_rate[0],
            m => panic!("{}: unknown metric {m:?}", p.name()),
        };
        let allowed = margin(p.figure, p.episodes);
        eprintln!(
            "{}: {} {got:.4} on {EPISODES} episodes, recorded {:.4} on {}",
            p.name(),
            p.metric,
            p.figure,
            p.episodes
        );
        assert!(
            (got - p.figure).abs() <= allowed,
            "{}: {} {got} on {EPISODES} episodes, recorded {} on {} (allowed +-{allowed:.3})",
            p.name(),
            p.metric,
            p.figure,
            p.episodes
        );
    }
}

#[test]
fn the_margin_is_as_stated() {
    assert!((margin(0.5, 1024) - (4.0 * (0.25f64 * (5.0 / 1024.0)).sqrt() + 0.02)).abs() < 1e-12);
    assert!(margin(0.5, 1024) < 0.16 && margin(0.0, 1024) == 0.02);
}
