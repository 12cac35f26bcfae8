//! The layer stage's settings: how many layers, how they are clustered, the context and
//! the completion.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// The most layers any mode produces (layer ids are `u16`; beyond this the hidden regions get
/// too thin to inpaint).
pub const MAX_LAYERS: usize = 64;

/// How many depth intervals the clustering makes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LayerCount {
    /// Exactly `n` Ward clusters (fewer when the depth has fewer distinct values). Make-It-4D
    /// uses 3.
    Count(usize),
    /// As many clusters as the scene has, by a resolution-independent criterion: the Ward
    /// dendrogram is cut where a merge would add more than `relative_cost·T` to the
    /// within-cluster sum of squares (`T`: the total sum of squares of the disparity). Both
    /// scale with the pixel count, so the same scene at any resolution gets the same layers.
    Auto {
        /// `τ` in `[0, 1]`: smaller gives more layers. 3D Cinemagraphy's `distance_threshold = 5`
        /// on its 10×-subsampled 512² disparity corresponds to roughly `τ ≈ 0.1`.
        relative_cost: f32,
        /// Upper bound on the count.
        max_layers: usize,
    },
}

impl Default for LayerCount {
    fn default() -> Self {
        LayerCount::Auto {
            relative_cost: 0.05,
            max_layers: 6,
        }
    }
}

/// Which partition of the disparity histogram the thresholds come from. Both minimise Ward's
/// objective, the within-cluster sum of squares of the disparity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClusterMethod {
    /// The exact minimum for the chosen count (optimal 1-D k-means by dynamic programming,
    /// [`cluster::OptimalPartitions`](super::cluster::OptimalPartitions)). Its boundaries stay put
    /// when the resolution changes.
    #[default]
    Optimal,
    /// Greedy Ward agglomeration by adjacent merges
    /// ([`cluster::WardTree`](super::cluster::WardTree)), as 3D Photography, 3D Cinemagraphy and
    /// Make-It-4D do with scikit-learn. On continuous disparity distributions its boundaries move
    /// with the resolution (early merges are made on histogram noise and never undone).
    Ward,
}

/// Parameters of the layering (everything [`plan_layers`](super::plan_layers) needs besides the
/// depth).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LayerParams {
    /// Fixed or automatic layer count.
    pub mode: LayerCount,
    /// Exact optimum or greedy Ward.
    pub method: ClusterMethod,
    /// User overrides of the thresholds `d_1 … d_{L+1}` (depths), one slot per threshold; `None`
    /// keeps the clustered value. Extra slots beyond `L + 1` are ignored. Thresholds dragged past
    /// each other are *re-sorted* (the thresholds are a set of cut depths, whatever handle moved
    /// them), and an interval left with no pixels makes no layer.
    pub overrides: Vec<Option<f32>>,
    /// Side `e` of the square erosion of `context_i = erode(D ≥ d_i, e×e)`, pixels.
    pub erode_px: usize,
    /// Border `b` around the context's bounding box that limits the hole, pixels.
    pub border_px: usize,
    /// A layer whose context has fewer pixels than this is merged into the previous one
    /// (together with every layer behind it: contexts shrink with depth).
    pub min_context_px: usize,
    /// A layer with fewer pixels of its own than this is merged into the neighbour closer in
    /// disparity.
    pub min_layer_px: usize,
    /// Window of the depth-edge refinement (masked median), pixels; 0 or 1 turns it off.
    pub edge_window_px: usize,
    /// Depth ratio `max Z / min Z` within the window above which a layer boundary counts as a
    /// depth discontinuity (and is refined).
    pub edge_depth_ratio: f32,
    /// Bins of the disparity histogram the clustering runs on.
    pub histogram_bins: usize,
    /// With a sky mask ([`plan_layers_with_sky`](super::plan_layers_with_sky)), the sky is a layer
    /// of its own, the farthest: the rest of the scene is clustered without it and one cut is added
    /// between the farthest non-sky depth and the sky (see
    /// [`sky_thresholds`](super::sky_thresholds)). Clustered together in disparity, the sky and
    /// distant mountains share a layer, and the ridge between them tears open with nothing behind
    /// it as soon as the camera moves.
    pub sky_layer: bool,
}

impl Default for LayerParams {
    fn default() -> Self {
        Self {
            mode: LayerCount::default(),
            method: ClusterMethod::default(),
            overrides: Vec::new(),
            erode_px: 10,
            border_px: 40,
            min_context_px: 10,
            min_layer_px: 10,
            edge_window_px: 11,
            edge_depth_ratio: 1.3,
            histogram_bins: 4096,
            sky_layer: true,
        }
    }
}

impl LayerParams {
    /// Checks every value; the message names the field at fault.
    pub fn validate(&self) -> Result<()> {
        match self.mode {
            LayerCount::Count(n) if n == 0 || n > MAX_LAYERS => {
                return Err(Error::invalid(format!(
                    "layers: count {n} is outside 1..={MAX_LAYERS}"
                )));
            }
            LayerCount::Auto {
                relative_cost,
                max_layers,
            } => {
                if !relative_cost.is_finite() || !(0.0..=1.0).contains(&relative_cost) {
                    return Err(Error::invalid(format!(
                        "layers: relative_cost {relative_cost} is outside [0, 1]"
                    )));
                }
                if max_layers == 0 || max_layers > MAX_LAYERS {
                    return Err(Error::invalid(format!(
                        "layers: max_layers {max_layers} is outside 1..={MAX_LAYERS}"
                    )));
                }
            }
            LayerCount::Count(_) => {}
        }
        if let Some((i, v)) = self
            .overrides
            .iter()
            .enumerate()
            .find_map(|(i, o)| o.filter(|v| !(v.is_finite() && *v > 0.0)).map(|v| (i, v)))
        {
            return Err(Error::invalid(format!(
                "layers: threshold override {i} is {v}; it must be a finite depth > 0"
            )));
        }
        if !self.edge_depth_ratio.is_finite() || self.edge_depth_ratio < 1.0 {
            return Err(Error::invalid(format!(
                "layers: edge_depth_ratio {} must be finite and ≥ 1",
                self.edge_depth_ratio
            )));
        }
        if self.histogram_bins < 2 || self.histogram_bins > 1 << 20 {
            return Err(Error::invalid(format!(
                "layers: histogram_bins {} is outside 2..=1048576",
                self.histogram_bins
            )));
        }
        Ok(())
    }
}
