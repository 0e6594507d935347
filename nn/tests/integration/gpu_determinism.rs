//! Training steps on the GPU give the same bits every time, whether or not the tape is
//! profiled (a profiled tape waits for the device after every op, which splits the batches
//! of queued kernels differently; the values must not depend on it). Feature `gpu`; CI runs
//! these on Mesa's lavapipe.
#![cfg(feature = "gpu")]

use nn::message_passing::{Aggregation, EdgeDistance, EdgeList, MessagePassingConfig};
use nn::{Adam, AdamConfig, Linear, ParamStore, SubeqMessagePassing, VectorLinear, clip_elementwise};
use tensor::{Device, Tape, Tensor};

/// Scenes of `E` entities, every ordered pair an edge (the shape of `shnn_step` in
/// `nn/benches/train_step.rs`, smaller).
const SCENES: usize = 6;
const E: usize = 4;

/// The parameters and losses after `steps` Adam steps of a two-round subequivariant message
/// passing on the GPU, the tape profiled or not.
fn train(steps: usize, profiled: bool) -> (Vec<Vec<f32>>, Vec<f32>) {
    let n = SCENES * E;
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(3);
    let (we, emb_h, mp, wu) = {
        let mut s = store.scope("", &mut init);
        let we = VectorLinear::new(&mut s.sub("We"), 4, 8).unwrap();
        let emb_h = Linear::new(&mut s.sub("emb_h"), 5, 16).unwrap();
        let cfg = MessagePassingConfig {
            vectors: 8,
            scalars: 16,
            hidden: 16,
            layers: 2,
            distance: EdgeDistance::Raw,
            aggregation: Aggregation::Mean,
            gravity: None,
            edge_scalars: 0,
        };
        let mp = SubeqMessagePassing::new(&mut s.sub("mp"), cfg).unwrap();
        let wu = Linear::with_options(&mut s.sub("Wu"), 8, 1, false, nn::Init::LecunUniform).unwrap();
        (we, emb_h, mp, wu)
    };
    store.to_device(Device::Gpu).unwrap();
    // Z0 [n, 3, 4]: three vectors of fixed values, then g = (0, 0, -1) as the 4th channel.
    let z0: Vec<f64> = (0..n * 12)
        .map(|i| match i % 12 {
            3 | 7 => 0.0,
            11 => -1.0,
            _ => ((i * 37 % 23) as f64) / 11.5 - 1.0,
        })
        .collect();
    let h0: Vec<f64> = (0..n * 5).map(|i| ((i * 13 % 17) as f64) / 8.5 - 1.0).collect();
    let z0 = Tensor::from_f64(&z0, &[n, 3, 4]).unwrap().to_device(Device::Gpu).unwrap();
    let h0 = Tensor::from_f64(&h0, &[n, 5]).unwrap().to_device(Device::Gpu).unwrap();
    let edges = EdgeList::fully_connected(SCENES, E);
    let mut adam = Adam::new(AdamConfig::default(), &store);
    let mut losses = Vec::new();
    for _ in 0..steps {
        let tape = Tape::on(Device::Gpu);
        if profiled {
            tape.enable_profiling();
        }
        let p = store.bind(&tape);
        let z0v = tape.constant(z0.clone());
        let x = z0v.narrow(2, 0, 1).unwrap();
        let mut z = we.forward(&p, z0v).unwrap();
        let mut h = emb_h.forward(&p, tape.constant(h0.clone())).unwrap();
        for _ in 0..2 {
            (z, h) = mp.forward(&p, z, h, x, &edges).unwrap();
        }
        let u = wu.forward(&p, z).unwrap().reshape(&[n, 3]).unwrap();
        let loss =
            u.square().sum(1, false).unwrap().add(h.square().mean(1, false).unwrap()).unwrap().mean_all().unwrap();
        let mut grads = p.grads(&tape.backward(loss).unwrap());
        clip_elementwise(&mut grads, 0.1);
        adam.step(&mut store, &grads).unwrap();
        losses.push(loss.value().to_host().unwrap().item().unwrap());
    }
    (store.values().iter().map(|v| v.to_host().unwrap().to_vec()).collect(), losses)
}

#[test]
fn gpu_training_steps_give_the_same_bits_with_and_without_profiling() {
    let steps = 4;
    let (params, losses) = train(steps, false);
    assert!(losses.iter().all(|l| l.is_finite()), "{losses:?}");
    assert_ne!(losses[0], losses[steps - 1], "the steps move the parameters");
    let (again, losses_again) = train(steps, false);
    assert_eq!(losses_again, losses, "a second run");
    assert!(again == params, "a second run's parameters differ");
    let (profiled, losses_profiled) = train(steps, true);
    assert_eq!(losses_profiled, losses, "a profiled run");
    assert!(profiled == params, "a profiled run's parameters differ");
}
