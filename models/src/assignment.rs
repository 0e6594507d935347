//! Task assignment (paper section 3, "Task Assignment", and Algorithm 1): which object
//! (goal ball, opponent) each agent is linked to in the entity-level graph.
//!
//! All methods work on a distance matrix `D[i, j]` (agent `i`, object `j`, row-major) and
//! write, for every object, the agent it is assigned to. An [`Assigner`] owns its scratch
//! buffers, so assigning the scenes of a batch one after the other allocates nothing.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// How agents are linked to objects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AssignmentMethod {
    /// Algorithm 1: objects in order, each takes the nearest agent still free.
    Greedy,
    /// The assignment of minimal total distance (Hungarian algorithm), which the paper
    /// could not run inside JAX.
    Hungarian,
    /// A uniformly random one-to-one assignment (ablation).
    Stochastic,
    /// No assignment: the entity graph stays fully connected (ablation).
    None,
    /// A co-learnable assignment (the SHNN family and the release's MLPs): drawn from a
    /// Plackett-Luce distribution over learned pair scores ([`crate::assignment_learned`])
    /// by the model, which hands it to the graph builder. Without scores
    /// ([`Assigner::assign`]) it falls back to Algorithm 1, the distribution's
    /// zero-temperature limit.
    Learned,
}

impl AssignmentMethod {
    /// Parses `greedy`, `hungarian`, `stochastic`, `none` or `learned`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "greedy" => Ok(Self::Greedy),
            "hungarian" => Ok(Self::Hungarian),
            "stochastic" => Ok(Self::Stochastic),
            "none" => Ok(Self::None),
            "learned" => Ok(Self::Learned),
            _ => Err(format!("unknown assignment `{s}` (expected greedy, hungarian, stochastic, none or learned)")),
        }
    }
}

/// Marks an object left without an agent (only when there are more objects than agents).
pub const UNASSIGNED: usize = usize::MAX;

/// Reusable assignment solver for up to `max_agents` x `max_objects` problems.
#[derive(Clone, Debug)]
pub struct Assigner {
    free: Vec<bool>,
    perm: Vec<usize>,
    // Hungarian potentials and bookkeeping (1-based as in the classical formulation).
    u: Vec<f64>,
    v: Vec<f64>,
    p: Vec<usize>,
    way: Vec<usize>,
    minv: Vec<f64>,
    used: Vec<bool>,
}

impl Assigner {
    /// Scratch space for problems of at most `max_agents` agents and `max_objects` objects.
    pub fn new(max_agents: usize, max_objects: usize) -> Self {
        let n = max_agents + 1;
        Self {
            free: vec![true; max_agents],
            perm: (0..max_agents).collect(),
            u: vec![0.0; max_objects + 1],
            v: vec![0.0; n],
            p: vec![0; n],
            way: vec![0; n],
            minv: vec![0.0; n],
            used: vec![false; n],
        }
    }

    /// Assigns the `m` objects of the `n x m` distance matrix `dist` (row-major, agent rows)
    /// to distinct agents, writing the agent of object `j` to `out[j]` (or [`UNASSIGNED`]).
    /// `rng` is only used by [`AssignmentMethod::Stochastic`]. With
    /// [`AssignmentMethod::None`] every entry is [`UNASSIGNED`]; [`AssignmentMethod::Learned`]
    /// has no scores here and is solved as Algorithm 1 (greedy).
    pub fn assign(
        &mut self,
        method: AssignmentMethod,
        dist: &[f64],
        n: usize,
        m: usize,
        out: &mut [usize],
        rng: &mut ChaCha8Rng,
    ) {
        assert!(dist.len() == n * m && out.len() == m, "distance matrix {n} x {m} and {} outputs", out.len());
        assert!(n <= self.free.len() && m < self.u.len(), "problem larger than the assigner's capacity");
        match method {
            AssignmentMethod::Greedy | AssignmentMethod::Learned => self.greedy(dist, n, m, out),
            AssignmentMethod::Hungarian => self.hungarian(dist, n, m, out),
            AssignmentMethod::Stochastic => self.stochastic(n, m, out, rng),
            AssignmentMethod::None => out.fill(UNASSIGNED),
        }
    }

    /// Algorithm 1: for each object `j` in order, `i = argmin_k D[k, j]` over free agents
    /// (the lowest index on ties), then agent `i` is no longer free.
    fn greedy(&mut self, dist: &[f64], n: usize, m: usize, out: &mut [usize]) {
        let free = &mut self.free[..n];
        free.fill(true);
        for (j, o) in out.iter_mut().enumerate().take(m) {
            let mut best = UNASSIGNED;
            for i in 0..n {
                if free[i] && (best == UNASSIGNED || dist[i * m + j] < dist[best * m + j]) {
                    best = i;
                }
            }
            if best != UNASSIGNED {
                free[best] = false;
            }
            *o = best;
        }
    }

    /// A random one-to-one assignment: a Fisher–Yates shuffle of the agents, object `j`
    /// gets the `j`-th.
    fn stochastic(&mut self, n: usize, m: usize, out: &mut [usize], rng: &mut ChaCha8Rng) {
        let perm = &mut self.perm[..n];
        for (i, p) in perm.iter_mut().enumerate() {
            *p = i;
        }
        for i in (1..n).rev() {
            let j = rng.random_range(0..=i);
            perm.swap(i, j);
        }
        for (j, o) in out.iter_mut().enumerate().take(m) {
            *o = if j < n { perm[j] } else { UNASSIGNED };
        }
    }

    /// Minimum-cost assignment by the Hungarian algorithm with potentials (O(m^2 n)),
    /// objects as rows and agents as columns. MeBen always has at least as many agents as
    /// objects; for the other case (allowed in user compositions) the transposed problem is
    /// solved, on freshly allocated scratch, and surplus objects stay unassigned.
    fn hungarian(&mut self, dist: &[f64], n: usize, m: usize, out: &mut [usize]) {
        if m > n {
            // Transposed: assign agents to objects, then invert.
            out.fill(UNASSIGNED);
            let mut tmp = vec![UNASSIGNED; n];
            let mut t = Assigner::new(m, n);
            let dt: Vec<f64> = (0..m * n).map(|x| dist[(x % n) * m + x / n]).collect();
            t.hungarian(&dt, m, n, &mut tmp);
            for (i, &j) in tmp.iter().enumerate() {
                if j != UNASSIGNED {
                    out[j] = i;
                }
            }
            return;
        }
        let inf = f64::INFINITY;
        let cost = |row: usize, col: usize| dist[(col - 1) * m + (row - 1)]; // row = object, col = agent (1-based)
        let (u, v, p, way, minv, used) =
            (&mut self.u, &mut self.v, &mut self.p, &mut self.way, &mut self.minv, &mut self.used);
        u[..=m].fill(0.0);
        v[..=n].fill(0.0);
        p[..=n].fill(0);
        way[..=n].fill(0);
        for row in 1..=m {
            p[0] = row;
            let mut j0 = 0;
            minv[..=n].fill(inf);
            used[..=n].fill(false);
            loop {
                used[j0] = true;
                let i0 = p[j0];
                let mut delta = inf;
                let mut j1 = 0;
                for j in 1..=n {
                    if !used[j] {
                        let cur = cost(i0, j) - u[i0] - v[j];
                        if cur < minv[j] {
                            minv[j] = cur;
                            way[j] = j0;
                        }
                        if minv[j] < delta {
                            delta = minv[j];
                            j1 = j;
                        }
                    }
                }
                for j in 0..=n {
                    if used[j] {
                        u[p[j]] += delta;
                        v[j] -= delta;
                    } else {
                        minv[j] -= delta;
                    }
                }
                j0 = j1;
                if p[j0] == 0 {
                    break;
                }
            }
            loop {
                let j1 = way[j0];
                p[j0] = p[j1];
                j0 = j1;
                if j0 == 0 {
                    break;
                }
            }
        }
        out.fill(UNASSIGNED);
        for j in 1..=n {
            if p[j] != 0 {
                out[p[j] - 1] = j - 1;
            }
        }
    }
}

/// Euclidean distances `D[i, j] = |p_j - p_i|` between agent roots and object positions,
/// written into `out` (row-major, agent rows).
pub fn distance_matrix(agents: &[[f64; 3]], objects: &[[f64; 3]], out: &mut [f64]) {
    let m = objects.len();
    for (i, a) in agents.iter().enumerate() {
        for (j, o) in objects.iter().enumerate() {
            let d = [o[0] - a[0], o[1] - a[1], o[2] - a[2]];
            out[i * m + j] = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        }
    }
}
