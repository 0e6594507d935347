//! Bring your own model: the example `rl/examples/custom_policy.rs`, a policy written against
//! the public API only, trains with the library's MAPPO (issue 43 item 1).

#[allow(dead_code)]
#[path = "../../examples/custom_policy.rs"]
mod example;

use envs::tasks::StartMode;
use example::{FlatPolicies, train};
use rl::{EvalOptions, Preset, TrainConfig, Trainer};

/// The quick preset on `team_reach/1_ant`, shrunk to a one-second iteration.
fn small() -> TrainConfig {
    let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
    c.num_envs = 16;
    c.batch_size = 16;
    c.num_minibatches = 2;
    c.epochs = 2;
    c
}

#[test]
fn a_custom_policy_trains_one_iteration_and_moves_its_parameters() {
    let config = small();
    let before = Trainer::with_policies(&config, &FlatPolicies { hidden: 64 }).unwrap();
    let (trainer, stats) = train(&config, 1).unwrap();
    // The run records the custom model's name, not the configuration's zoo model.
    assert_eq!(trainer.config.model, "flat_mlp");
    assert_eq!(trainer.iteration, 1);
    assert_eq!(trainer.env_steps, config.steps_per_iteration());
    let s = &stats[0].losses[0];
    assert!(s.policy_loss.is_finite() && s.value_loss.is_finite() && s.entropy.is_finite(), "{s:?}");
    // Every parameter is the factory's (the heads and the critic) and the update moved them.
    let (old, new) = (&before.teams[0].store, &trainer.teams[0].store);
    assert!(new.names().iter().any(|n| n.starts_with("team0.critic.")), "{:?}", new.names());
    assert!(new.names().iter().any(|n| n.starts_with("team0.actor.0.")), "{:?}", new.names());
    assert_eq!(old.names(), new.names());
    for (name, (a, b)) in old.names().iter().zip(old.values().iter().zip(new.values())) {
        assert_ne!(a.data(), b.data(), "{name} did not change");
    }
    // The evaluator acts with it too.
    let eval = trainer.evaluate(&EvalOptions::new(8, true, 1, StartMode::Random)).unwrap();
    assert_eq!(eval.episodes, 8);
}

#[test]
fn a_custom_policy_trains_to_the_same_bits_twice() {
    let config = small();
    let (a, _) = train(&config, 1).unwrap();
    let (b, _) = train(&config, 1).unwrap();
    for (x, y) in a.teams[0].store.values().iter().zip(b.teams[0].store.values()) {
        assert_eq!(x.data(), y.data());
    }
}

#[test]
fn a_custom_run_resumes_from_its_checkpoint_with_the_same_factory() {
    let config = small();
    let (straight, _) = train(&config, 2).unwrap();
    let (first, _) = train(&config, 1).unwrap();
    let c = first.checkpoint(0.0, &[]).unwrap();
    let path = std::path::Path::new("in-memory");
    let mut resumed = Trainer::from_checkpoint_with_policies(&c, &config, path, &FlatPolicies { hidden: 64 }).unwrap();
    resumed.iterate().unwrap();
    straight.teams[0].store.values().iter().zip(resumed.teams[0].store.values()).for_each(|(x, y)| {
        assert_eq!(x.data(), y.data());
    });
    // The zoo's resume refuses it: the checkpoint's model is not one of the zoo's.
    let err = Trainer::from_checkpoint(&c, &config, path).err().expect("a zoo resume of a custom run");
    assert!(err.to_string().contains("flat_mlp"), "{err}");
}
