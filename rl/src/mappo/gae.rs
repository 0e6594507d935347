//! Generalised advantage estimation (Schulman et al. 2016) over unrolls, with termination and
//! truncation kept apart (MEBEN.md section 8): on a time-limit truncation the next state's
//! value is that of the true final observation, `V(s_final)`, and the advantage recursion is
//! cut (the next step belongs to a new episode); on termination the next value is 0.
//!
//! `delta_t = r_t + gamma (1 - term_t) V_next(t) - V(s_t)`, with
//! `V_next(t) = V(s_final,t)` if `trunc_t` else `V(s_{t+1})`;
//! `A_t = delta_t + gamma lambda (1 - term_t)(1 - trunc_t) A_{t+1}`, `A_T = 0`;
//! value targets `v_t = A_t + V(s_t)`.
//!
//! Arrays are time-major, as in a [`Minibatch`]: entry `(t, j)` of `T` steps of `M` unrolls
//! is at `t M + j`.

use crate::mappo::minibatch::{Minibatch, NO_FINAL};

/// Advantages and value targets of the minibatch's transitions, `[T, M]` each (module docs),
/// from `values`, one per observation row of `mb` (`(T + 1) M + K`: `V(s_t)`, row `T` the
/// state after the unroll, then `V(s_final)` of the truncated transitions, at their
/// [`Minibatch::final_row`]). Computed in f64. Panics when the lengths disagree (the
/// trainer's internal arrays).
pub fn gae(mb: &Minibatch, values: &[f32], discount: f64, lambda: f64) -> (Vec<f32>, Vec<f32>) {
    let (t_len, m) = (mb.steps, mb.unrolls);
    let n = t_len * m;
    assert_eq!(mb.rewards.len(), n);
    assert_eq!(mb.terminated.len(), n);
    assert_eq!(mb.truncated.len(), n);
    assert_eq!(mb.final_row.len(), n);
    assert!(values.len() >= (t_len + 1) * m);
    let mut adv = vec![0.0f32; n];
    let mut targets = vec![0.0f32; n];
    for j in 0..m {
        let mut next_adv = 0.0f64;
        for t in (0..t_len).rev() {
            let i = t * m + j;
            let v = values[i] as f64;
            let (term, trunc) = (mb.terminated[i], mb.truncated[i]);
            let next_v = if term {
                0.0
            } else if trunc {
                if mb.final_row[i] == NO_FINAL { 0.0 } else { values[mb.final_row[i] as usize] as f64 }
            } else {
                values[i + m] as f64
            };
            let delta = mb.rewards[i] as f64 + discount * next_v - v;
            let carry = if term || trunc { 0.0 } else { discount * lambda * next_adv };
            let a = delta + carry;
            adv[i] = a as f32;
            targets[i] = (a + v) as f32;
            next_adv = a;
        }
    }
    (adv, targets)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minibatch of `m` unrolls of `steps` steps with these arrays (no observations).
    fn unrolls(steps: usize, m: usize, r: &[f32], term: &[bool], trunc: &[bool], final_row: &[u32]) -> Minibatch {
        Minibatch {
            steps,
            unrolls: m,
            rewards: r.to_vec(),
            terminated: term.to_vec(),
            truncated: trunc.to_vec(),
            final_row: final_row.to_vec(),
            ..Minibatch::default()
        }
    }

    fn close(a: &[f32], b: &[f64]) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((*x as f64 - y).abs() < 1e-5, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn hand_computed_sequence_without_ends() {
        // T = 3, M = 1, gamma 0.5, lambda 0.5.
        let r = [1.0, 2.0, 3.0];
        let v = [0.5, 1.0, 1.5, 2.0];
        let mb = unrolls(3, 1, &r, &[false; 3], &[false; 3], &[NO_FINAL; 3]);
        let (a, t) = gae(&mb, &v, 0.5, 0.5);
        // deltas: 1 + .5*1 - .5 = 1; 2 + .5*1.5 - 1 = 1.75; 3 + .5*2 - 1.5 = 2.5
        // A2 = 2.5; A1 = 1.75 + .25*2.5 = 2.375; A0 = 1 + .25*2.375 = 1.59375
        close(&a, &[1.59375, 2.375, 2.5]);
        close(&t, &[2.09375, 3.375, 4.0]);
    }

    #[test]
    fn termination_and_truncation() {
        // Two unrolls (M = 2), T = 2, gamma 0.9, lambda 0.8. Unroll 0 terminates at t = 0;
        // unroll 1 is truncated at t = 0 with V(s_final) = 10.
        let r = [1.0, 1.0, 2.0, 2.0]; // (t0,j0) (t0,j1) (t1,j0) (t1,j1)
        let term = [true, false, false, false];
        let trunc = [false, true, false, false];
        // Rows: (T + 1) M = 6 states, then the final observation of the truncated one (row 6).
        let v = [0.5, 0.5, 3.0, 3.0, 4.0, 4.0, 10.0];
        let mb = unrolls(2, 2, &r, &term, &trunc, &[NO_FINAL, 6, NO_FINAL, NO_FINAL]);
        let (a, t) = gae(&mb, &v, 0.9, 0.8);
        // t1 (both): delta = 2 + .9*4 - 3 = 2.6 = A.
        // (t0, j0): terminated: delta = 1 - .5 = .5, no carry.
        // (t0, j1): truncated: delta = 1 + .9*10 - .5 = 9.5, no carry.
        close(&a, &[0.5, 9.5, 2.6, 2.6]);
        close(&t, &[1.0, 10.0, 5.6, 5.6]);
    }
}
