//! Subequivariant message passing over an edge list: paper eqs. (vector-interaction) to
//! (update-mlp), in the form of the reference release (and of the `shnn_step` benchmark).
//!
//! For an edge `i -> j` with relative position `e = x_j - x_i`:
//! - `Z_ij = [Z_i | Z_j | e (| g)] W1` (eq. vector-interaction, mixed to `m` channels),
//! - `h_ij = [h_i, h_j, |e| or RBF(|e|), s_ij]` (eq. scalar-interaction; `s_ij` are optional
//!   invariant edge scalars the caller supplies, e.g. the reference release's critic's RBF
//!   expansion of the distance and an edge-type one-hot),
//! - `(M_ij, m_ij) = φ_g(Z_ij, h_ij)` (eq. message-mlp): `c = MLP_e([Z_ij^T Z_ij, h_ij]) / (||Z_ij^T Z_ij|| + 1)`,
//!   `M_ij = Z_ij c_vec`, `m_ij = c_scalar`,
//! - `M_i, m_i` = mean (or sum) over the edges leaving `i` (eq. message-aggregation),
//! - `(Z_i, h_i) += ψ_g([M_i, Z_i], [m_i, h_i])` (eq. update-mlp) with `Y = [Z_i | M_i (| g)] W2`,
//!   `c' = MLP_n([Y^T Y, h_i, m_i]) / (||Y^T Y|| + 1)`, `Z_i += Y c'_vec`, `h_i += c'_scalar`.

use tensor::{Activation, Float, Var};

use crate::equivariant::{VectorLinear, mix_by_invariants};
use crate::error::{NnError, Result};
use crate::linear::Mlp;
use crate::params::{Bound, Scope};
use crate::rbf::RadialBasis;

/// Directed edges `src -> dst`, sorted by `src` (messages are aggregated at `src`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EdgeList {
    /// Source node of each edge (non-decreasing).
    pub src: Vec<usize>,
    /// Destination node of each edge.
    pub dst: Vec<usize>,
    /// Number of nodes.
    pub num_nodes: usize,
}

impl EdgeList {
    /// Checks the edges: equal lengths, indices in range, sources sorted.
    pub fn new(src: Vec<usize>, dst: Vec<usize>, num_nodes: usize) -> Result<Self> {
        if src.len() != dst.len() {
            return Err(NnError::Config(format!("edge list: {} sources and {} destinations", src.len(), dst.len())));
        }
        if let Some(&i) = src.iter().chain(&dst).find(|&&i| i >= num_nodes) {
            return Err(NnError::Config(format!("edge list: node {i} out of range for {num_nodes} nodes")));
        }
        if src.windows(2).any(|w| w[0] > w[1]) {
            return Err(NnError::Config("edge list: sources must be sorted".into()));
        }
        Ok(Self { src, dst, num_nodes })
    }

    /// Every ordered pair `(i, j)`, `i != j`, within each of `groups` consecutive blocks of
    /// `size` nodes (a batch of fully connected graphs).
    pub fn fully_connected(groups: usize, size: usize) -> Self {
        let (mut src, mut dst) = (Vec::new(), Vec::new());
        for g in 0..groups {
            for i in 0..size {
                for j in 0..size {
                    if i != j {
                        src.push(g * size + i);
                        dst.push(g * size + j);
                    }
                }
            }
        }
        Self { src, dst, num_nodes: groups * size }
    }

    /// Number of edges.
    pub fn len(&self) -> usize {
        self.src.len()
    }

    /// Whether there is no edge.
    pub fn is_empty(&self) -> bool {
        self.src.is_empty()
    }
}

/// How messages are combined at a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aggregation {
    /// Mean over incoming messages (the release's choice).
    Mean,
    /// Sum (the paper's eq. (message-aggregation)).
    Sum,
}

/// Edge scalar derived from the distance `|e|`.
#[derive(Clone, Debug)]
pub enum EdgeDistance {
    /// The distance itself (1 feature).
    Raw,
    /// A radial-basis expansion.
    Rbf(RadialBasis),
    /// No distance feature.
    None,
}

impl EdgeDistance {
    fn size(&self) -> usize {
        match self {
            EdgeDistance::Raw => 1,
            EdgeDistance::Rbf(r) => r.size(),
            EdgeDistance::None => 0,
        }
    }
}

/// The edges' geometry a [`SubeqMessagePassing`] layer reads: `e = x_j - x_i` and the
/// distance feature of `|e|` ([`SubeqMessagePassing::edge_geometry`]).
#[derive(Clone, Copy, Debug)]
pub struct EdgeGeometry<'t, T: Float> {
    /// `x_j - x_i` per edge `[E, 3, 1]`.
    pub e: Var<'t, T>,
    /// The distance feature `[E, EdgeDistance::size()]`; `None` when the layer takes none.
    pub distance: Option<Var<'t, T>>,
}

/// Sizes and options of a [`SubeqMessagePassing`] layer.
#[derive(Clone, Debug)]
pub struct MessagePassingConfig {
    /// Vector channels `m` of the node features.
    pub vectors: usize,
    /// Scalar features `s` of the node features.
    pub scalars: usize,
    /// Hidden width of both MLPs.
    pub hidden: usize,
    /// Hidden layers of both MLPs.
    pub layers: usize,
    /// Edge distance feature.
    pub distance: EdgeDistance,
    /// Message aggregation.
    pub aggregation: Aggregation,
    /// Gravity channel appended before each mixing (`None`: no gravity inside the layer;
    /// full O(3) equivariance unless the inputs carry it).
    pub gravity: Option<[f64; 3]>,
    /// Invariant scalars per edge supplied by the caller ([`SubeqMessagePassing::forward_with`]).
    pub edge_scalars: usize,
}

/// One round of subequivariant message passing (see the module documentation).
#[derive(Clone, Debug)]
pub struct SubeqMessagePassing {
    /// `W1`: mixes `[Z_i | Z_j | e (| g)]` to `m` channels.
    pub w1: VectorLinear,
    /// `MLP_e` of the message function.
    pub mlp_e: Mlp,
    /// `W2`: mixes `[Z_i | M_i (| g)]` to `m` channels.
    pub w2: VectorLinear,
    /// `MLP_n` of the update function.
    pub mlp_n: Mlp,
    /// The configuration.
    pub config: MessagePassingConfig,
}

impl SubeqMessagePassing {
    /// Parameters `<scope>.{w1,w2}.weight`, `<scope>.{mlp_e,mlp_n}.<i>.{weight,bias}`.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, config: MessagePassingConfig) -> Result<Self> {
        let (m, sc, hd) = (config.vectors, config.scalars, config.hidden);
        if m == 0 || hd == 0 || config.layers == 0 {
            return Err(NnError::Config(format!(
                "message passing with {m} vectors, hidden {hd}, {} layers",
                config.layers
            )));
        }
        let g = usize::from(config.gravity.is_some());
        let hidden = |input: usize| {
            let mut v = vec![input];
            v.extend(std::iter::repeat_n(hd, config.layers));
            v.push(m * m + sc);
            v
        };
        let w1 = VectorLinear::new(&mut s.sub("w1"), 2 * m + 1 + g, m)?;
        let edge_in = m * m + 2 * sc + config.distance.size() + config.edge_scalars;
        let mlp_e = Mlp::new(&mut s.sub("mlp_e"), &hidden(edge_in), Activation::Relu)?;
        let w2 = VectorLinear::new(&mut s.sub("w2"), 2 * m + g, m)?;
        let mlp_n = Mlp::new(&mut s.sub("mlp_n"), &hidden(m * m + 2 * sc), Activation::Relu)?;
        Ok(Self { w1, mlp_e, w2, mlp_n, config })
    }

    /// One round: `z: [N, 3, m]`, `h: [N, s]`, positions `x: [N, 3, 1]` -> updated `(z, h)`
    /// (a layer built with `edge_scalars: 0`).
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z: Var<'t, T>,
        h: Var<'t, T>,
        x: Var<'t, T>,
        edges: &EdgeList,
    ) -> Result<(Var<'t, T>, Var<'t, T>)> {
        self.forward_with(p, z, h, x, edges, None)
    }

    /// [`SubeqMessagePassing::forward`] with the caller's invariant edge scalars
    /// `edge_scalars: [E, config.edge_scalars]` appended to `h_ij` (`None` when the layer
    /// takes none).
    pub fn forward_with<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z: Var<'t, T>,
        h: Var<'t, T>,
        x: Var<'t, T>,
        edges: &EdgeList,
        edge_scalars: Option<Var<'t, T>>,
    ) -> Result<(Var<'t, T>, Var<'t, T>)> {
        let geometry = self.edge_geometry(x, edges)?;
        self.forward_over(p, z, h, &geometry, edges, edge_scalars)
    }

    /// The edges' geometry this layer reads over positions `x: [N, 3, 1]`: `e = x_j - x_i`
    /// and the distance feature of its configuration (eqs. vector-interaction,
    /// scalar-interaction). Message passing does not move the positions, so rounds over the
    /// same positions share it: compute it once and pass it to each
    /// [`SubeqMessagePassing::forward_over`] (the same values as recomputing it per round).
    pub fn edge_geometry<'t, T: Float>(&self, x: Var<'t, T>, edges: &EdgeList) -> Result<EdgeGeometry<'t, T>> {
        let n = edges.num_nodes;
        if x.shape() != [n, 3, 1] {
            return Err(NnError::Config(format!("message passing expects x [{n}, 3, 1]; got {:?}", x.shape())));
        }
        let e = x.index_select(0, &edges.dst)?.sub(x.index_select(0, &edges.src)?)?; // [E, 3, 1]
        let dist = || -> Result<Var<'t, T>> { Ok(e.reshape(&[edges.len(), 3])?.norm_last(1e-12)) }; // [E, 1]
        let distance = match &self.config.distance {
            EdgeDistance::Raw => Some(dist()?),
            EdgeDistance::Rbf(r) => Some(r.forward(dist()?)?),
            EdgeDistance::None => None,
        };
        Ok(EdgeGeometry { e, distance })
    }

    /// An error unless `z: [N, 3, m]` and `h: [N, s]`.
    fn check_nodes<T: Float>(&self, z: Var<'_, T>, h: Var<'_, T>, edges: &EdgeList) -> Result<()> {
        let (n, m, s) = (edges.num_nodes, self.config.vectors, self.config.scalars);
        if z.shape() != [n, 3, m] || h.shape() != [n, s] {
            return Err(NnError::Config(format!(
                "message passing expects z [{n}, 3, {m}] and h [{n}, {s}]; got {:?} and {:?}",
                z.shape(),
                h.shape(),
            )));
        }
        Ok(())
    }

    /// [`SubeqMessagePassing::forward_with`] over a geometry computed by
    /// [`SubeqMessagePassing::edge_geometry`] for the same edges.
    pub fn forward_over<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z: Var<'t, T>,
        h: Var<'t, T>,
        geometry: &EdgeGeometry<'t, T>,
        edges: &EdgeList,
        edge_scalars: Option<Var<'t, T>>,
    ) -> Result<(Var<'t, T>, Var<'t, T>)> {
        let cfg = &self.config;
        let (m, s) = (cfg.vectors, cfg.scalars);
        let n = edges.num_nodes;
        let e_cnt = edges.len();
        self.check_nodes(z, h, edges)?;
        let e = geometry.e;
        if e.shape() != [e_cnt, 3, 1] || geometry.distance.is_some() != (cfg.distance.size() > 0) {
            return Err(NnError::Config(format!(
                "message passing over {e_cnt} edges got a geometry of e {:?} and {} distance",
                e.shape(),
                if geometry.distance.is_some() { "a" } else { "no" }
            )));
        }
        // Edge features (eqs. vector-interaction, scalar-interaction).
        let zi = z.index_select(0, &edges.src)?;
        let zj = z.index_select(0, &edges.dst)?;
        // W1 [Z_i | Z_j | e (| g)], without building the concatenation.
        let zij = self.w1.forward_channels(p, &[zi, zj, e], cfg.gravity)?; // [E, 3, m]
        let mut scalars = vec![h.index_select(0, &edges.src)?, h.index_select(0, &edges.dst)?];
        scalars.extend(geometry.distance);
        match edge_scalars {
            Some(s) if cfg.edge_scalars > 0 && s.shape() == [e_cnt, cfg.edge_scalars] => scalars.push(s),
            None if cfg.edge_scalars == 0 => {}
            other => {
                return Err(NnError::Config(format!(
                    "message passing takes {} edge scalars for {e_cnt} edges; got {:?}",
                    cfg.edge_scalars,
                    other.map(|s| s.shape())
                )));
            }
        }
        // Messages (eq. message-mlp).
        let (mz, mh) = mix_by_invariants(p, &self.mlp_e, zij, &scalars, m, s)?;
        // Aggregation at the source node (eq. message-aggregation).
        let agg = |v: Var<'t, T>, width: usize| -> Result<Var<'t, T>> {
            let flat = v.reshape(&[e_cnt, width])?;
            Ok(match cfg.aggregation {
                Aggregation::Mean => flat.segment_mean(&edges.src, n)?,
                Aggregation::Sum => flat.segment_sum(&edges.src, n)?,
            })
        };
        let mz = agg(mz, 3 * m)?.reshape(&[n, 3, m])?;
        let mh = agg(mh, s)?;
        // Node update (eq. update-mlp).
        let y = self.w2.forward_channels(p, &[z, mz], cfg.gravity)?;
        let (dz, dh) = mix_by_invariants(p, &self.mlp_n, y, &[h, mh], m, s)?;
        Ok((z.add(dz)?, h.add(dh)?))
    }
}
