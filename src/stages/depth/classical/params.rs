//! The classical estimator's parameters, their defaults and their check.

use super::*;

/// Parameters of [`ClassicalDepth`]. Every field has a documented default
/// (`ClassicalDepthParams::default()`); the project file stores them with `#[serde(default)]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClassicalDepthParams {
    /// User override of the horizon line, as a fraction of the image height from the top
    /// (0 = top row, 1 = bottom row). `None` (default): detected automatically.
    pub horizon: Option<f32>,
    /// Horizon used when it is not overridden and no sky is found, fraction of height from the
    /// top. Default 0.5 (a level camera).
    pub default_horizon: f32,
    /// Camera height above the ground plane, metres; sets the metric scale of the depth
    /// (`Z = h·fy/(v − v_h)` on the ground). Default 1.6.
    pub camera_height_m: f32,
    /// The cues are computed on a copy whose longer side is at most this many pixels.
    /// Default 384.
    pub work_size_px: usize,
    /// Sky candidates have a luma at least this (sRGB-encoded, `[0, 1]`). Default 0.18.
    pub sky_min_luma: f32,
    /// Sky candidates have a local texture (blurred luma gradient magnitude per working pixel)
    /// at most this. Default 0.03.
    pub sky_max_texture: f32,
    /// Pixels brighter than this × the median luma are sky candidates whatever their texture.
    /// Default 2.0.
    pub sky_bright_factor: f32,
    /// Sky is cut off this far below the detected horizon, fraction of the height (water and
    /// fog below the horizon are not sky). Default 0.05.
    pub sky_below_horizon: f32,
    /// Weight of the position (ground plane + pop-up) cue in the fusion. Default 0.5.
    pub ground_weight: f32,
    /// Share of a plain top-to-bottom disparity ramp mixed into the ground prior, so that
    /// structures above the horizon are not all at the same depth. Default 0.3.
    pub background_ramp: f32,
    /// Colour step (sum of absolute RGB differences between vertically adjacent working
    /// pixels) at which the pop-up carry is halved. Default 0.2 (bark and foliage texture below it;
    /// 0.1 cut tree trunks off from the ground they stand on).
    pub popup_edge: f32,
    /// How far a vertical structure carries its ground-contact nearness upward before it
    /// fades, fraction of the image height. Default 1.0.
    pub popup_carry: f32,
    /// Weight of the object (figure-ground against the border) cue, scaled down by the
    /// border's incoherence and by haziness. Default 1.0.
    pub object_weight: f32,
    /// Colour difference (RGB Euclidean, `[0, 1]` units) of one standard deviation in the
    /// object cue's similarity kernel. Default 0.4.
    pub object_colour_scale: f32,
    /// Texture difference of one standard deviation in the object cue's kernel. Default 0.01.
    pub object_texture_scale: f32,
    /// Border coherence (mean similarity of two border samples) below which the object cue
    /// is off: a border of many different things is not one background. Default 0.2.
    pub object_coherence_onset: f32,
    /// Border coherence at which the object cue has its full weight. Default 0.4.
    pub object_coherence_full: f32,
    /// Width of the border band sampled as "background", fraction of the shorter side.
    /// Default 0.05.
    pub border_band: f32,
    /// Blur radius (Gaussian σ, fraction of the longer working side) of the object cue's
    /// structure test. Default 0.06.
    pub object_structure_sigma: f32,
    /// Object-cue structure (the share of its variance that survives that blur: 1 = whole
    /// regions, 0 = pixel-scale speckle) below which the cue is off: a cue that only follows
    /// texture (moss, foliage, gravel) marks no object. Default 0.15.
    pub object_structure_onset: f32,
    /// Object-cue structure at which the cue has its full weight. Default 0.25.
    pub object_structure_full: f32,
    /// Weight of the local detail (focus / figure-ground) cue in photos where the landscape
    /// cues do not apply (no sky, no reflection) and the border is not one background (the
    /// weight fades out as the border's coherence rises from `object_coherence_onset` to
    /// `object_coherence_full`: against one background the object cue decides, and a forest
    /// floor or canopy has no figure): sharper, more detailed than its surroundings is
    /// nearer. Added to the fused nearness as `weight · clamp(local / scale, −½, ½)`.
    /// Default 0.5.
    pub detail_weight: f32,
    /// Local detail difference (natural log of the gradient energy against its
    /// neighbourhood) that counts as a full step of the detail cue. Default 3.0.
    pub detail_scale: f32,
    /// Weight of the aerial-perspective cue above the horizon of a landscape with a sky:
    /// what is farther looks more like the sky (paler, bluer, less contrast), so a colour far
    /// from the sky's is nearer (a red tree before a pale mountain range). Added as
    /// `weight · min(‖c − c_sky‖ / aerial_scale, 1) · (1 − position)`, fading out just below
    /// the horizon (a structure the pop-up already carries forward gains nothing).
    /// Default 0.15.
    pub aerial_weight: f32,
    /// RGB distance (`[0, 1]` units, Euclidean) from the sky's median colour that counts as
    /// fully unlike the sky. Default 0.6.
    pub aerial_scale: f32,
    /// Weight of the haze cue when the image is fully hazy. Default 0.5.
    pub haze_weight: f32,
    /// Weight of the defocus cue ([`defocus_cue`]: in focus is nearer) where the landscape
    /// cues do not apply, times the cue's own confidence (how much sharper the sharp part of
    /// the picture is than its blurred part). Default 1.0.
    pub defocus_weight: f32,
    /// Parsimony: a nearness step per working pixel that counts as a sure edge of a
    /// confident cue (sky, figure, pop-up contact, focus border); relief away from such edges
    /// is flattened to the smooth surface through it. Default 0.05.
    pub parsimony_edge: f32,
    /// Reach (spatial σ) of that smooth surface's filter, fraction of the long working side
    /// (0: nothing is flattened).
    /// Default 0.01 (pixel-scale texture goes, region-scale shape stays: at 0.02 and 0.03
    /// the Aloe pair's δ<1.25 fell to 0.707 and 0.697, and its novel view by 0.1 dB).
    pub parsimony_radius: f32,
    /// Median normalised dark channel at which the haze cue starts to count. Default 0.5.
    pub haze_onset: f32,
    /// Median normalised dark channel at which the haze cue counts fully. Default 0.75.
    pub haze_full: f32,
    /// Ratio of the farthest to the nearest non-sky depth. Default 100 (the released
    /// Make-It-4D code's `ε = 0.01`).
    pub max_depth_ratio: f32,
    /// Sky depth = this × the median non-sky depth (at least the farthest non-sky depth).
    /// Default 100.
    pub far_plane_factor: f32,
    /// Radius of the edge-aware refinement, fraction of the longer image side. Default 0.0125.
    pub refine_radius: f32,
    /// Regulariser of the guided filter (squared luma units). Default 0.03.
    pub refine_epsilon: f32,
}

impl Default for ClassicalDepthParams {
    fn default() -> Self {
        Self {
            horizon: None,
            default_horizon: 0.5,
            camera_height_m: 1.6,
            work_size_px: 384,
            sky_min_luma: 0.18,
            sky_max_texture: 0.03,
            sky_bright_factor: 2.0,
            sky_below_horizon: 0.05,
            ground_weight: 0.5,
            background_ramp: 0.3,
            popup_edge: 0.2,
            popup_carry: 1.0,
            object_weight: 1.0,
            object_colour_scale: 0.4,
            object_texture_scale: 0.01,
            object_coherence_onset: 0.2,
            object_coherence_full: 0.4,
            border_band: 0.05,
            object_structure_sigma: 0.06,
            object_structure_onset: 0.15,
            object_structure_full: 0.25,
            detail_weight: 0.5,
            detail_scale: 3.0,
            aerial_weight: 0.15,
            aerial_scale: 0.6,
            haze_weight: 0.5,
            defocus_weight: 1.0,
            parsimony_edge: 0.05,
            parsimony_radius: 0.01,
            haze_onset: 0.5,
            haze_full: 0.75,
            max_depth_ratio: 100.0,
            far_plane_factor: 100.0,
            refine_radius: 0.0125,
            refine_epsilon: 0.03,
        }
    }
}

impl ClassicalDepthParams {
    /// Checks every field; the message names the first bad one.
    pub fn validate(&self) -> Result<()> {
        if let Some(h) = self.horizon
            && !(h.is_finite() && (-1.0..=2.0).contains(&h))
        {
            return Err(Error::invalid(format!(
                "horizon {h} must be a finite fraction of the image height in [-1, 2]"
            )));
        }
        let positive = [
            ("camera_height_m", self.camera_height_m),
            ("popup_edge", self.popup_edge),
            ("popup_carry", self.popup_carry),
            ("object_colour_scale", self.object_colour_scale),
            ("object_texture_scale", self.object_texture_scale),
            ("detail_scale", self.detail_scale),
            ("aerial_scale", self.aerial_scale),
            ("refine_epsilon", self.refine_epsilon),
            ("parsimony_edge", self.parsimony_edge),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("{name} must be > 0 (got {v})")));
            }
        }
        let non_negative = [
            ("ground_weight", self.ground_weight),
            ("object_weight", self.object_weight),
            ("haze_weight", self.haze_weight),
            ("defocus_weight", self.defocus_weight),
            ("parsimony_radius", self.parsimony_radius),
            ("detail_weight", self.detail_weight),
            ("aerial_weight", self.aerial_weight),
            ("background_ramp", self.background_ramp),
            ("border_band", self.border_band),
            ("object_structure_sigma", self.object_structure_sigma),
            ("refine_radius", self.refine_radius),
            ("sky_min_luma", self.sky_min_luma),
            ("sky_max_texture", self.sky_max_texture),
            ("sky_bright_factor", self.sky_bright_factor),
            ("sky_below_horizon", self.sky_below_horizon),
            ("haze_onset", self.haze_onset),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("{name} must be ≥ 0 (got {v})")));
            }
        }
        if !(self.default_horizon.is_finite()) {
            return Err(Error::invalid("default_horizon must be finite"));
        }
        if !(self.object_coherence_full.is_finite()
            && self.object_coherence_onset.is_finite()
            && self.object_coherence_full > self.object_coherence_onset)
        {
            return Err(Error::invalid(
                "object_coherence_full must be greater than object_coherence_onset",
            ));
        }
        if !(self.object_structure_onset.is_finite()
            && self.object_structure_full.is_finite()
            && self.object_structure_full > self.object_structure_onset)
        {
            return Err(Error::invalid(
                "object_structure_full must be greater than object_structure_onset",
            ));
        }
        if !(self.haze_full.is_finite() && self.haze_full > self.haze_onset) {
            return Err(Error::invalid("haze_full must be greater than haze_onset"));
        }
        if !(self.max_depth_ratio.is_finite() && self.max_depth_ratio > 1.0) {
            return Err(Error::invalid("max_depth_ratio must be > 1"));
        }
        if !(self.far_plane_factor.is_finite() && self.far_plane_factor >= 1.0) {
            return Err(Error::invalid("far_plane_factor must be ≥ 1"));
        }
        if self.work_size_px < 8 {
            return Err(Error::invalid("work_size_px must be ≥ 8"));
        }
        if self.ground_weight + self.object_weight + self.haze_weight <= 0.0 {
            return Err(Error::invalid("at least one cue weight must be > 0"));
        }
        Ok(())
    }
}
