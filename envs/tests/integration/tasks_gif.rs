//! Animated GIFs of recorded episodes: they decode (with the `gif` crate) to the requested
//! size and frame count, something is drawn, Sumo frames change over time, and bad options
//! are errors naming the field.

use envs::tasks::TaskError;
use envs::tasks::render::{GifOptions, Trajectory, record_episode};

/// Decodes `bytes` and returns (width, height, every frame composited as the viewer shows
/// it: sub-rectangles over the kept previous image, transparent pixels unchanged, the
/// global palette).
fn decode(bytes: &[u8]) -> (u16, u16, Vec<Vec<u8>>, Vec<u8>) {
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::Indexed);
    let mut d = options.read_info(bytes).expect("a GIF header");
    let (w, h) = (d.width(), d.height());
    let palette = d.global_palette().expect("a global palette").to_vec();
    assert_eq!(d.repeat(), gif::Repeat::Infinite);
    let mut screen = vec![0u8; w as usize * h as usize];
    let mut frames = Vec::new();
    while let Some(f) = d.read_next_frame().expect("a decodable frame") {
        assert!(f.left + f.width <= w && f.top + f.height <= h, "frame outside the screen");
        for y in 0..f.height as usize {
            for x in 0..f.width as usize {
                let p = f.buffer[y * f.width as usize + x];
                if Some(p) != f.transparent {
                    screen[(f.top as usize + y) * w as usize + f.left as usize + x] = p;
                }
            }
        }
        frames.push(screen.clone());
    }
    (w, h, frames, palette)
}

/// Pixels of `frame` whose palette colour is `rgb`.
fn count(frame: &[u8], palette: &[u8], rgb: [u8; 3]) -> usize {
    frame.iter().filter(|&&p| palette[3 * p as usize..3 * p as usize + 3] == rgb).count()
}

/// The most frequent colour of a frame (the background).
fn background(frame: &[u8]) -> u8 {
    let mut counts = [0usize; 256];
    frame.iter().for_each(|&p| counts[p as usize] += 1);
    (0..=255u8).max_by_key(|&c| counts[c as usize]).unwrap()
}

fn episode(name: &str) -> Trajectory {
    let traj = record_episode(name, 2, 30, |_obs, a| a.fill(0.0)).unwrap();
    assert_eq!(traj.len(), 31);
    traj
}

#[test]
fn reach_and_sumo_episodes_encode_to_decodable_gifs() {
    for (name, options, n_frames) in [
        ("team_reach/1_ant", GifOptions { width: 160, height: 120, frame_step: 1, delay_cs: 5 }, 31),
        ("team_sumo/2_ants", GifOptions { width: 200, height: 150, frame_step: 3, delay_cs: 15 }, 11),
        ("team_sumo/2_ants", GifOptions::default(), 16),
    ] {
        let traj = episode(name);
        let bytes = traj.to_gif(&options).unwrap();
        assert!(bytes.starts_with(b"GIF89a") || bytes.starts_with(b"GIF87a"));
        let (w, h, frames, palette) = decode(&bytes);
        assert_eq!((w, h), (options.width, options.height), "{name}");
        assert_eq!(frames.len(), n_frames, "{name}: one frame per frame_step recorded frames");
        for (i, f) in frames.iter().enumerate() {
            let bg = background(f);
            let drawn = f.iter().filter(|&&p| p != bg).count();
            assert!(drawn > f.len() / 100, "{name}: frame {i} is almost all background ({drawn} pixels drawn)");
            assert!(f.iter().collect::<std::collections::BTreeSet<_>>().len() >= 4, "{name}: too few colours");
            // The agents in the HTML player's colours: team 0 (or agent 0) blue, Sumo's team 1
            // orange; the goal ball yellow, Sumo's centre ball grey.
            let area = w as usize * h as usize;
            let (blue, orange) = (count(f, &palette, [0x3b, 0x7d, 0xd8]), count(f, &palette, [0xe0, 0x7b, 0x39]));
            assert!(blue > area / 400, "{name}: frame {i}: {blue} blue pixels");
            let sumo = name.starts_with("team_sumo");
            assert_eq!(orange > area / 400, sumo, "{name}: frame {i}: {orange} orange pixels");
            let ball = if sumo { [0x88; 3] } else { [0xe8, 0xc5, 0x47] };
            assert!(count(f, &palette, ball) > 0, "{name}: frame {i}: no ball");
        }
        if name.starts_with("team_sumo") {
            let changed = frames.windows(2).filter(|p| p[0] != p[1]).count();
            assert!(changed * 2 >= frames.len() - 1, "{name}: only {changed} of {} frames changed", frames.len() - 1);
            assert_ne!(frames.first(), frames.last(), "{name}: the bodies did not move");
        }
        // Deterministic: the same trajectory gives the same bytes.
        assert_eq!(traj.to_gif(&options).unwrap(), bytes);
    }
}

#[test]
fn bad_gif_options_are_errors_naming_the_field() {
    let traj = record_episode("team_reach/1_ant", 0, 2, |_obs, a| a.fill(0.0)).unwrap();
    let ok = GifOptions { width: 16, height: 12, frame_step: 1, delay_cs: 1 };
    assert!(traj.to_gif(&ok).is_ok());
    for (field, options) in [
        ("width", GifOptions { width: 0, ..ok }),
        ("height", GifOptions { height: 0, ..ok }),
        ("frame_step", GifOptions { frame_step: 0, ..ok }),
        ("delay_cs", GifOptions { delay_cs: 0, ..ok }),
    ] {
        match traj.to_gif(&options) {
            Err(e @ TaskError::BadArgument { .. }) => {
                assert!(matches!(&e, TaskError::BadArgument { what, .. } if what == field), "{e}");
                assert!(e.to_string().contains(field), "{e}");
            }
            other => panic!("{field} = 0 gave {other:?}"),
        }
    }
    // A frame step longer than the episode keeps the first frame; a 1 x 1 image still works.
    let (_, _, frames, _) = decode(&traj.to_gif(&GifOptions { frame_step: 100, ..ok }).unwrap());
    assert_eq!(frames.len(), 1);
    let (w, h, _, _) = decode(&traj.to_gif(&GifOptions { width: 1, height: 1, ..ok }).unwrap());
    assert_eq!((w, h), (1, 1));
    // An empty trajectory has nothing to show.
    let empty = Trajectory::new(&traj.scene);
    assert!(matches!(empty.to_gif(&ok), Err(TaskError::BadArgument { what, .. }) if what == "trajectory"));
}

/// A recorded task assignment is drawn on top of each frame as a dashed line in each
/// agent's colour: the pixels it changes are all agent 0's blue or agent 1's orange, both
/// lines are visible, and a swap of the assignment mid-episode changes the later frames.
#[test]
fn the_task_assignment_is_drawn_in_each_agents_colour() {
    let mut traj = record_episode("team_reach/2_ants", 4, 10, |_obs, a| a.fill(0.0)).unwrap();
    let options = GifOptions { width: 240, height: 180, frame_step: 1, delay_cs: 5 };
    let (_, _, plain, palette) = decode(&traj.to_gif(&options).unwrap());
    // Agents 0 and 1, then the balls 2 and 3; swapped from step 5 on.
    let rows = |swap_at: usize| -> Vec<Vec<Option<usize>>> {
        (0..10).map(|k| if k < swap_at { vec![Some(2), Some(3)] } else { vec![Some(3), Some(2)] }).collect()
    };
    traj.set_assignments(rows(5)).unwrap();
    let (_, _, marked, _) = decode(&traj.to_gif(&options).unwrap());
    let (blue, orange) = ([0x3b, 0x7d, 0xd8], [0xe0, 0x7b, 0x39]);
    for (i, (p, m)) in plain.iter().zip(&marked).enumerate() {
        let changed: Vec<u8> = p.iter().zip(m).filter(|(a, b)| a != b).map(|(_, b)| *b).collect();
        let colour = |c: &u8| palette[3 * *c as usize..3 * *c as usize + 3].to_vec();
        assert!(changed.iter().all(|c| colour(c) == blue || colour(c) == orange), "frame {i}: other colours changed");
        let (nb, no) = (
            changed.iter().filter(|c| colour(c) == blue).count(),
            changed.iter().filter(|c| colour(c) == orange).count(),
        );
        assert!(nb >= 10 && no >= 10, "frame {i}: {nb} blue and {no} orange mark pixels");
    }
    traj.set_assignments(rows(10)).unwrap();
    let (_, _, unswapped, _) = decode(&traj.to_gif(&options).unwrap());
    // Step k's assignment is drawn on frame k (the last step's on the final frame).
    assert!(unswapped[..5] == marked[..5], "the frames before the swap changed");
    assert!(unswapped[5..].iter().zip(&marked[5..]).all(|(a, b)| a != b), "a frame after the swap did not change");
}
