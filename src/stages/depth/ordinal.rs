//! Ordinal depth evaluation: the Depth-in-the-Wild protocol (Chen et al., NeurIPS 2016).
//!
//! An annotation is a pair of points a person can order at a glance, point `a` nearer than point
//! `b`. A depth map orders the pair by its depth at the two points, each the median of the 5×5
//! pixels around the point; the score is the weighted human disagreement rate
//! `WHDR = wrong / pairs`, where a pair counts as wrong when the map orders it the other way or
//! ties it (relative depth difference under [`TIE_TOLERANCE`]). Lower is better; the vertical ramp
//! (lower in the image = nearer) is the trivial baseline to beat.
//!
//! The annotation file is JSON: `{"photos": {"PATH": [[[xa, ya], [xb, yb]], …], …}}`, paths
//! relative to a root folder, coordinates fractions of width and height (0 = left/top).

use super::DepthEstimator;
use super::classical::ClassicalDepth;
use super::eval::{ConstantDepth, VerticalRampDepth};
use crate::error::{Error, Result};
use crate::geometry::Intrinsics;
use crate::progress::Progress;
use crate::raster::GrayRaster;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Two depths whose relative difference is below this count as a tie (a wrong answer).
pub const TIE_TOLERANCE: f32 = 1e-3;

/// Half the side of the median window around an annotated point (5×5).
pub const MEDIAN_RADIUS: usize = 2;

/// One annotated pair: `nearer` is closer to the camera than `farther`. Coordinates are
/// fractions of the image width and height.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrdinalPair {
    /// The nearer point `[x, y]`.
    pub nearer: [f32; 2],
    /// The farther point `[x, y]`.
    pub farther: [f32; 2],
}

/// An annotation file: pairs per photo, keyed by the photo's path relative to the root.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OrdinalAnnotations {
    /// Pairs per photo path, in path order.
    pub photos: BTreeMap<String, Vec<OrdinalPair>>,
}

#[derive(Deserialize)]
struct AnnotationFile {
    photos: BTreeMap<String, Vec<[[f32; 2]; 2]>>,
}

impl OrdinalAnnotations {
    /// Parses the JSON text of an annotation file; errors name the bad field and, for a point
    /// outside the image, the photo and the pair.
    pub fn parse(text: &str) -> Result<Self> {
        let de = &mut serde_json::Deserializer::from_str(text);
        let file: AnnotationFile = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            Error::invalid(format!("field `{path}`: {}", e.inner()))
        })?;
        let mut photos = BTreeMap::new();
        for (photo, pairs) in file.photos {
            let mut parsed = Vec::with_capacity(pairs.len());
            for (i, [a, b]) in pairs.into_iter().enumerate() {
                for p in [a, b] {
                    if !p.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)) {
                        return Err(Error::invalid(format!(
                            "field `photos.{photo}[{i}]`: point [{}, {}] is not inside the \
                             image (fractions in [0, 1])",
                            p[0], p[1]
                        )));
                    }
                }
                parsed.push(OrdinalPair {
                    nearer: a,
                    farther: b,
                });
            }
            photos.insert(photo, parsed);
        }
        Ok(Self { photos })
    }

    /// Reads and parses an annotation file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
        Self::parse(&text).map_err(|e| Error::file(path, e))
    }

    /// Number of pairs over all photos.
    pub fn pair_count(&self) -> usize {
        self.photos.values().map(Vec::len).sum()
    }
}

/// The median of the depths in the `(2r + 1)²` window around the point `(fx·W, fy·H)`
/// (clipped to the image); non-finite values are skipped. `None` for an empty raster or a
/// window with no finite value.
pub fn median_depth_at(depth: &GrayRaster, fx: f32, fy: f32, radius: usize) -> Option<f32> {
    let (w, h) = depth.size();
    if w == 0 || h == 0 {
        return None;
    }
    let cx = ((fx * w as f32).floor() as isize).clamp(0, w as isize - 1);
    let cy = ((fy * h as f32).floor() as isize).clamp(0, h as isize - 1);
    let r = radius as isize;
    let mut values = Vec::with_capacity((2 * radius + 1).pow(2));
    for y in (cy - r).max(0)..=(cy + r).min(h as isize - 1) {
        for x in (cx - r).max(0)..=(cx + r).min(w as isize - 1) {
            let v = depth.at(x as usize, y as usize);
            if v.is_finite() {
                values.push(v);
            }
        }
    }
    if values.is_empty() {
        return None;
    }
    values.sort_by(f32::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    })
}

/// Whether `depth` orders `pair` the way the annotator did: strictly nearer, beyond a tie.
pub fn orders_correctly(depth: &GrayRaster, pair: &OrdinalPair) -> bool {
    let za = median_depth_at(depth, pair.nearer[0], pair.nearer[1], MEDIAN_RADIUS);
    let zb = median_depth_at(depth, pair.farther[0], pair.farther[1], MEDIAN_RADIUS);
    match (za, zb) {
        (Some(a), Some(b)) => b - a > TIE_TOLERANCE * a.abs().max(b.abs()),
        _ => false,
    }
}

/// The indices of the pairs `depth` orders wrongly or ties.
pub fn wrong_pairs(depth: &GrayRaster, pairs: &[OrdinalPair]) -> Vec<usize> {
    (0..pairs.len())
        .filter(|&i| !orders_correctly(depth, &pairs[i]))
        .collect()
}

/// Scores of one photo: wrong pairs per estimator, in [`OrdinalTable::estimators`] order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrdinalPhotoRow {
    /// The photo's path as written in the annotation file.
    pub photo: String,
    /// Its number of pairs.
    pub pairs: usize,
    /// Wrongly ordered (or tied) pairs per estimator.
    pub wrong: Vec<usize>,
    /// Per estimator, the indices (into the photo's pairs) of those wrong pairs.
    pub wrong_pairs: Vec<Vec<usize>>,
}

/// Scores of several estimators over an annotation set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrdinalTable {
    /// Estimator names, one column each.
    pub estimators: Vec<String>,
    /// One row per photo, in path order.
    pub rows: Vec<OrdinalPhotoRow>,
}

/// `wrong / pairs`, 0 for no pairs.
fn rate(wrong: usize, pairs: usize) -> f64 {
    if pairs == 0 {
        0.0
    } else {
        wrong as f64 / pairs as f64
    }
}

impl OrdinalTable {
    /// The photo group of a path: its first folder (`photos/x.jpg` → `photos`), or `.`.
    pub fn group_of(photo: &str) -> &str {
        photo.split_once('/').map_or(".", |(g, _)| g)
    }

    /// `(pairs, wrong per estimator)` summed over the rows for which `keep` holds.
    pub fn totals(&self, keep: impl Fn(&OrdinalPhotoRow) -> bool) -> (usize, Vec<usize>) {
        let mut pairs = 0;
        let mut wrong = vec![0; self.estimators.len()];
        for row in self.rows.iter().filter(|r| keep(r)) {
            pairs += row.pairs;
            for (w, r) in wrong.iter_mut().zip(&row.wrong) {
                *w += r;
            }
        }
        (pairs, wrong)
    }

    /// The photo groups, in order of first appearance.
    pub fn groups(&self) -> Vec<String> {
        let mut groups: Vec<String> = Vec::new();
        for row in &self.rows {
            let g = Self::group_of(&row.photo);
            if !groups.iter().any(|x| x == g) {
                groups.push(g.to_string());
            }
        }
        groups
    }

    /// WHDR over all photos per estimator.
    pub fn overall(&self) -> Vec<f64> {
        let (pairs, wrong) = self.totals(|_| true);
        wrong.iter().map(|&w| rate(w, pairs)).collect()
    }

    /// WHDR over one group per estimator.
    pub fn group(&self, group: &str) -> Vec<f64> {
        let (pairs, wrong) = self.totals(|r| Self::group_of(&r.photo) == group);
        wrong.iter().map(|&w| rate(w, pairs)).collect()
    }

    /// A markdown table: one row per photo, then one per group and the overall figure.
    pub fn to_markdown(&self) -> String {
        let mut s = String::from("| photo | pairs |");
        for e in &self.estimators {
            s.push_str(&format!(" {e} WHDR ↓ |"));
        }
        s.push_str("\n|---|---:|");
        s.push_str(&"---:|".repeat(self.estimators.len()));
        s.push('\n');
        let line = |s: &mut String, label: &str, pairs: usize, wrong: &[usize]| {
            s.push_str(&format!("| {label} | {pairs} |"));
            for &w in wrong {
                s.push_str(&format!(" {:.3} ({w}) |", rate(w, pairs)));
            }
            s.push('\n');
        };
        for row in &self.rows {
            line(&mut s, &row.photo, row.pairs, &row.wrong);
        }
        for g in self.groups() {
            let (pairs, wrong) = self.totals(|r| Self::group_of(&r.photo) == g);
            line(&mut s, &format!("**{g}/**"), pairs, &wrong);
        }
        let (pairs, wrong) = self.totals(|_| true);
        line(&mut s, "**overall**", pairs, &wrong);
        s.push_str(
            "\nWHDR: share of annotated pairs ordered wrongly or tied (in brackets: how many); \
             depth at a point = median of its 5×5 pixels.\n",
        );
        s
    }

    /// Pretty-printed JSON, with the group and overall rates.
    pub fn to_json(&self) -> Result<String> {
        #[derive(Serialize)]
        struct Json<'a> {
            estimators: &'a [String],
            rows: &'a [OrdinalPhotoRow],
            groups: BTreeMap<String, Vec<f64>>,
            overall: Vec<f64>,
        }
        let groups = self
            .groups()
            .into_iter()
            .map(|g| {
                let r = self.group(&g);
                (g, r)
            })
            .collect();
        serde_json::to_string_pretty(&Json {
            estimators: &self.estimators,
            rows: &self.rows,
            groups,
            overall: self.overall(),
        })
        .map_err(|e| Error::invalid(format!("json: {e}")))
    }
}

/// Options of [`eval_ordinal`].
#[derive(Default)]
pub struct OrdinalOptions<'a> {
    /// Folder the annotation paths are relative to.
    pub root: PathBuf,
    /// Estimators scored after the classical one and the two baselines.
    pub extra: Vec<&'a dyn DepthEstimator>,
    /// Writes each photo's classical depth preview here (`<stem>_depth.png`) when set.
    pub save_dir: Option<PathBuf>,
}

/// Scores the classical estimator (default parameters), the vertical-ramp and constant
/// baselines and `options.extra` on every annotated photo. A photo that cannot be read is an
/// error naming it.
pub fn eval_ordinal(
    annotations: &OrdinalAnnotations,
    options: &OrdinalOptions,
    progress: &Progress,
) -> Result<OrdinalTable> {
    let classical = ClassicalDepth::default();
    let mut estimators: Vec<&dyn DepthEstimator> =
        vec![&classical, &VerticalRampDepth, &ConstantDepth];
    estimators.extend(options.extra.iter().copied());
    if let Some(dir) = &options.save_dir {
        crate::image_io::prepare_output_dir(dir)?;
    }
    let count = annotations.photos.len().max(1) as f32;
    let mut rows = Vec::new();
    for (i, (photo, pairs)) in annotations.photos.iter().enumerate() {
        let sub = progress.sub(i as f32 / count, (i + 1) as f32 / count);
        sub.report(0.0, &format!("ordinal: {photo}"));
        sub.check()?;
        let path = options.root.join(photo);
        let image = crate::image_io::load_image(&path)?.rgb;
        let (w, h) = image.size();
        let intrinsics = Intrinsics::from_hfov(w, h, 60.0);
        let mut wrong = Vec::new();
        let mut wrong_indices = Vec::new();
        for (k, e) in estimators.iter().enumerate() {
            let estimate = e
                .estimate(&image, &intrinsics, &sub)
                .map_err(|err| Error::file(&path, format!("{}: {err}", e.name())))?;
            if k == 0
                && let Some(dir) = &options.save_dir
            {
                let stem = Path::new(photo)
                    .file_stem()
                    .map_or("photo".into(), |s| s.to_string_lossy().into_owned());
                let preview = super::preview::depth_preview(&estimate.depth, Some(&estimate.sky));
                crate::image_io::save_rgb_png(
                    &dir.join(format!("{stem}_depth.png")),
                    &preview,
                    false,
                )?;
            }
            let bad = wrong_pairs(&estimate.depth, pairs);
            wrong.push(bad.len());
            wrong_indices.push(bad);
        }
        rows.push(OrdinalPhotoRow {
            photo: photo.clone(),
            pairs: pairs.len(),
            wrong,
            wrong_pairs: wrong_indices,
        });
    }
    Ok(OrdinalTable {
        estimators: estimators.iter().map(|e| e.name().to_string()).collect(),
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Raster;

    fn pair(a: [f32; 2], b: [f32; 2]) -> OrdinalPair {
        OrdinalPair {
            nearer: a,
            farther: b,
        }
    }

    #[test]
    fn median_window_known_answer() {
        // Depth = x + 10·y on a 10×10 grid; the 5×5 median around (5, 5) is 55.
        let d = Raster::from_fn(10, 10, |x, y| (x + 10 * y) as f32);
        assert_eq!(median_depth_at(&d, 0.55, 0.55, 2), Some(55.0));
        // Clipped at the corner: 3×3 values {0,1,2,10,11,12,20,21,22}, median 11.
        assert_eq!(median_depth_at(&d, 0.0, 0.0, 2), Some(11.0));
        // An outlier in the window does not move the median.
        let mut spiked = Raster::new(10, 10, 1.0f32);
        spiked.set(5, 5, 1000.0);
        assert_eq!(median_depth_at(&spiked, 0.55, 0.55, 2), Some(1.0));
        assert_eq!(median_depth_at(&Raster::new(0, 0, 1.0), 0.5, 0.5, 2), None);
    }

    #[test]
    fn whdr_counts_wrong_and_tied_pairs() {
        // Depth grows upward (a ramp): lower = nearer.
        let d = Raster::from_fn(20, 20, |_, y| 100.0 - y as f32);
        let pairs = [
            pair([0.5, 0.9], [0.5, 0.1]), // right
            pair([0.5, 0.1], [0.5, 0.9]), // wrong
            pair([0.1, 0.5], [0.9, 0.5]), // tie → wrong
            pair([0.2, 0.8], [0.7, 0.3]), // right
        ];
        assert_eq!(wrong_pairs(&d, &pairs), vec![1, 2]);
        // The constant map ties every pair.
        assert_eq!(wrong_pairs(&Raster::new(20, 20, 5.0), &pairs).len(), 4);
    }

    #[test]
    fn annotations_parse_and_name_bad_fields() {
        let good = r#"{"about": "x", "photos": {"a/b.jpg": [[[0.5, 0.9], [0.5, 0.1]]]}}"#;
        let a = OrdinalAnnotations::parse(good).unwrap();
        assert_eq!(a.pair_count(), 1);
        assert_eq!(a.photos["a/b.jpg"][0], pair([0.5, 0.9], [0.5, 0.1]));
        let bad_shape = r#"{"photos": {"a.jpg": [[[0.5, 0.9]]]}}"#;
        let e = OrdinalAnnotations::parse(bad_shape)
            .unwrap_err()
            .to_string();
        assert!(e.contains("photos.a.jpg[0]"), "{e}");
        let outside = r#"{"photos": {"a.jpg": [[[0.5, 1.5], [0.5, 0.1]]]}}"#;
        let e = OrdinalAnnotations::parse(outside).unwrap_err().to_string();
        assert!(e.contains("photos.a.jpg[0]") && e.contains("1.5"), "{e}");
        let missing = r#"{"pairs": {}}"#;
        let e = OrdinalAnnotations::parse(missing).unwrap_err().to_string();
        assert!(e.contains("photos"), "{e}");
    }

    #[test]
    fn table_groups_and_totals() {
        let table = OrdinalTable {
            estimators: vec!["a".into(), "b".into()],
            rows: vec![
                OrdinalPhotoRow {
                    photo: "photos/x.jpg".into(),
                    pairs: 4,
                    wrong: vec![1, 2],
                    wrong_pairs: vec![vec![0], vec![0, 1]],
                },
                OrdinalPhotoRow {
                    photo: "wild/y.jpg".into(),
                    pairs: 6,
                    wrong: vec![0, 3],
                    wrong_pairs: vec![vec![], vec![0, 1, 2]],
                },
            ],
        };
        assert_eq!(table.groups(), vec!["photos", "wild"]);
        assert_eq!(table.group("photos"), vec![0.25, 0.5]);
        assert_eq!(table.group("wild"), vec![0.0, 0.5]);
        assert_eq!(table.overall(), vec![0.1, 0.5]);
        let md = table.to_markdown();
        assert!(
            md.contains("| **overall** | 10 | 0.100 (1) | 0.500 (5) |"),
            "{md}"
        );
        assert!(table.to_json().unwrap().contains("\"overall\""));
    }
}
