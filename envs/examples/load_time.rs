//! Times loading a generated model of `N` bodies, stage by stage: parsing and building
//! (`mjcf::load_str`, or the Brax config parser then `agent_model`), then `Data::new` and
//! one step. The figures in `docs/PERFORMANCE.md` ("Loading large models") come from it.
//!
//! ```text
//! cargo run --release -p envs --example load_time -- SHAPE N [SHAPE N ...]
//! ```
//!
//! Shapes: `mjcf-chain` (a free root then `N - 1` hinged capsules, each the child of the
//! previous one), `mjcf-star` (a free root with `N - 1` hinged capsules as its children),
//! `mjcf-free` (`N - 1` free spheres on a plane), `brax-chain` and `brax-star` (the same
//! two trees as one Brax agent, built as `agent_model` builds a MeBen agent).

use envs::brax::{BraxPhysics, agent_model, parse_config};
use envs::{Data, Model};
use std::fmt::Write;
use std::process::ExitCode;
use std::time::Instant;

/// MJCF text of a `shape` model with `n` bodies besides the world.
fn mjcf(shape: &str, n: usize) -> String {
    let mut s = String::from("<mujoco><worldbody>\n<geom type=\"plane\" size=\"40 40 40\" conaffinity=\"1\"/>\n");
    let capsule = "<geom type=\"capsule\" fromto=\"0 0 0 0.1 0 0.05\" size=\"0.03\" conaffinity=\"0\"/>";
    let hinge = |i: usize| format!("<joint name=\"j{i}\" type=\"hinge\" axis=\"0 1 0\" range=\"-30 30\"/>");
    match shape {
        "free" => {
            for i in 0..n {
                let (x, y) = (i % 100, i / 100);
                let _ = writeln!(
                    s,
                    "<body pos=\"{x} {y} 1\"><joint type=\"free\"/><geom type=\"sphere\" size=\"0.1\" conaffinity=\"0\"/></body>"
                );
            }
        }
        _ => {
            s.push_str(
                "<body pos=\"0 0 1\"><joint type=\"free\"/><geom type=\"sphere\" size=\"0.2\" conaffinity=\"0\"/>\n",
            );
            for i in 1..n {
                let close = if shape == "chain" { "" } else { "</body>" };
                let _ = writeln!(s, "<body pos=\"0.1 0 0\">{}{capsule}{close}", hinge(i));
            }
            let open = if shape == "chain" { n } else { 1 };
            s.push_str(&"</body>".repeat(open));
        }
    }
    s.push_str("</worldbody>\n<actuator>\n");
    if shape != "free" {
        for i in 1..n {
            let _ = writeln!(s, "<motor joint=\"j{i}\" gear=\"1\" ctrlrange=\"-1 1\" ctrllimited=\"true\"/>");
        }
    }
    s.push_str("</actuator></mujoco>\n");
    s
}

/// Brax config text of one agent of `n` bodies: a chain, or a star about body 0.
fn brax(shape: &str, n: usize) -> String {
    let mut s = String::new();
    for i in 0..n {
        let _ = writeln!(
            s,
            "bodies {{ name: \"b{i}\" colliders {{ capsule {{ radius: 0.05 length: 0.3 }} }} \
             inertia {{ x: 1 y: 1 z: 1 }} mass: 1 }}"
        );
    }
    for i in 1..n {
        let parent = if shape == "chain" { i - 1 } else { 0 };
        let _ = writeln!(
            s,
            "joints {{ name: \"j{i}\" parent_offset {{ x: 0.15 }} child_offset {{ x: -0.15 }} parent: \"b{parent}\" \
             child: \"b{i}\" angular_damping: 35 angle_limit {{ min: -30 max: 30 }} }}\n\
             actuators {{ name: \"j{i}\" joint: \"j{i}\" strength: 100 torque {{}} }}"
        );
    }
    s
}

fn run(shape: &str, n: usize) -> Result<(), String> {
    let t0 = Instant::now();
    let (kind, tree) = shape.split_once('-').ok_or_else(|| format!("unknown shape `{shape}`"))?;
    let (model, stages): (Model, String) = match (kind, tree) {
        ("mjcf", "chain" | "star" | "free") => {
            let text = mjcf(tree, n);
            let t = Instant::now();
            let m = envs::mjcf::load_str(&text, "generated.xml").map_err(|e| e.to_string())?;
            (m, format!("mjcf load {:.3} s", t.elapsed().as_secs_f64()))
        }
        ("brax", "chain" | "star") => {
            let text = brax(tree, n);
            let t = Instant::now();
            let config = parse_config(&text, "generated.txt").map_err(|e| e.to_string())?;
            let parse = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let (m, _) = agent_model(&config, &BraxPhysics::default()).map_err(|e| e.to_string())?;
            (m, format!("brax parse {parse:.3} s, agent_model {:.3} s", t.elapsed().as_secs_f64()))
        }
        _ => return Err(format!("unknown shape `{shape}` (mjcf-chain, mjcf-star, mjcf-free, brax-chain, brax-star)")),
    };
    let t = Instant::now();
    let mut d = Data::new(&model);
    let data = t.elapsed().as_secs_f64();
    let t = Instant::now();
    envs::step(&model, &mut d);
    let step = t.elapsed().as_secs_f64();
    println!(
        "{shape} {n}: {stages}, Data::new {data:.3} s, one step {step:.3} s; total {:.3} s \
         (bodies {}, nv {}, plane pairs {}, geom pairs {})",
        t0.elapsed().as_secs_f64(),
        model.bodies.len(),
        model.nv,
        model.plane_pairs.len(),
        model.geom_pairs.len()
    );
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() || !args.len().is_multiple_of(2) {
        eprintln!("usage: load_time SHAPE N [SHAPE N ...]");
        return ExitCode::FAILURE;
    }
    for pair in args.chunks(2) {
        let n = match pair[1].parse::<usize>() {
            Ok(n) if n >= 1 => n,
            _ => {
                eprintln!("error: N must be a whole number >= 1, got `{}`", pair[1]);
                return ExitCode::FAILURE;
            }
        };
        if let Err(e) = run(&pair[0], n) {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    }
    ExitCode::SUCCESS
}
