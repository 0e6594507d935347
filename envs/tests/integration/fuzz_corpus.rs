//! Replays the committed fuzzing corpora of the `envs` readers (`fuzz/corpus/<target>`, see
//! `fuzz/README.md`) through the same calls as the fuzz targets, on the stable toolchain:
//! every input must give `Ok` or `Err`, never a panic. The corpora hold the seeds, what
//! libFuzzer kept for new coverage (minimised with `cargo fuzz cmin`) and the inputs of the
//! crashes it found (`crash-*`), so each crash stays fixed.

#[path = "../../../fuzz/replay.rs"]
mod replay;

use replay::replay;

#[test]
fn the_mjcf_corpus_loads_or_fails_cleanly() {
    let ok =
        replay("mjcf", |data| std::str::from_utf8(data).is_ok_and(|t| envs::mjcf::load_str(t, "fuzz.xml").is_ok()));
    eprintln!("mjcf: {ok} inputs load");
    assert!(ok >= 14, "only {ok} inputs load: the corpus lost its valid models");
}

#[test]
fn the_brax_config_corpus_loads_or_fails_cleanly() {
    let dir = std::env::temp_dir().join(format!("envs-fuzz-brax-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("morphology.txt");
    let ok = replay("brax_config", |data| {
        let Ok(text) = std::str::from_utf8(data) else { return false };
        let Ok(config) = envs::brax::parse_config(text, "fuzz.txt") else { return false };
        let model = envs::brax::agent_model(&config, &envs::brax::BraxPhysics::default()).is_ok();
        std::fs::write(&file, data).unwrap();
        let scene = envs::tasks::Scene::from_name(&format!("team_reach:agents=ant+{}", file.display())).is_ok();
        model && scene
    });
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("brax_config: {ok} inputs build a scene");
    assert!(ok >= 4, "only {ok} inputs build a scene: the corpus lost its valid configs");
}

#[test]
fn the_controls_corpus_parses_or_fails_cleanly() {
    let ok = replay("controls", |data| match data.split_first() {
        Some((&n, rest)) => std::str::from_utf8(rest)
            .is_ok_and(|t| envs::rollout_tool::parse_controls(t, "fuzz.csv", usize::from(n % 32)).is_ok()),
        None => false,
    });
    eprintln!("controls: {ok} inputs parse");
    assert!(ok >= 2, "only {ok} inputs parse: the corpus lost its valid files");
}
