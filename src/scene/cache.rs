//! The stage caches: each stage's recent outputs keyed by a hash of its parameters and the key
//! of the stage before it ([`key_of`]), least recently used first, and the run statistics.

use super::Stage;
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::Serialize;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

/// How many outputs each stage keeps at most, keyed by the stage's inputs: returning to an
/// earlier state (undo, redo, deleting the key just added, switching a count back) finds every
/// stage cached. What the caches keep beyond the shown scene is also bounded in bytes
/// ([`spare_budget`]; [`SceneBuilder::trim`](super::SceneBuilder::trim)): a ten-thousand-edit
/// storm on a 1 MP photo otherwise filled four canvases of a wide orbit per stage (5.8 GB).
pub const CACHE_ENTRIES: usize = 4;

/// The least the stage caches may keep of outputs nothing else holds, bytes: a small scene's
/// whole earlier state fits.
pub const MIN_SPARE_BYTES: usize = 256 << 20;

/// Bytes an output holds on the heap (its rasters and point arrays; small fields are left
/// out): what keeping it in a stage cache costs.
pub trait CacheBytes {
    /// The bytes, approximately (within the few small fields left out).
    fn cache_bytes(&self) -> usize;
}

impl<T: CacheBytes> CacheBytes for Option<T> {
    fn cache_bytes(&self) -> usize {
        self.as_ref().map_or(0, CacheBytes::cache_bytes)
    }
}

impl<T: CacheBytes> CacheBytes for Arc<T> {
    fn cache_bytes(&self) -> usize {
        self.as_ref().cache_bytes()
    }
}

impl CacheBytes for crate::image_io::LoadedImage {
    fn cache_bytes(&self) -> usize {
        self.rgb.heap_bytes() + self.alpha.as_ref().map_or(0, |a| a.heap_bytes())
    }
}

impl CacheBytes for crate::stages::depth::DepthStageOutput {
    fn cache_bytes(&self) -> usize {
        let e = &self.estimate;
        e.depth.heap_bytes()
            + e.sky.heap_bytes()
            + e.confidence.heap_bytes()
            + self.cues.as_ref().map_or(0, |c| c.map.heap_bytes())
            + self.unedited.as_ref().map_or(0, |d| d.heap_bytes())
    }
}

impl CacheBytes for super::Canvas {
    fn cache_bytes(&self) -> usize {
        self.image.heap_bytes()
            + self.depth.heap_bytes()
            + self.sky.heap_bytes()
            + self.synthesised.heap_bytes()
    }
}

impl CacheBytes for crate::stages::layers::LayerPlan {
    fn cache_bytes(&self) -> usize {
        self.depth.heap_bytes()
            + self.labels.heap_bytes()
            + self
                .regions
                .iter()
                .map(|r| {
                    r.mask.heap_bytes()
                        + r.context.heap_bytes()
                        + r.hole.heap_bytes()
                        + r.hidden.heap_bytes()
                })
                .sum::<usize>()
    }
}

impl CacheBytes for crate::stages::layers::LayeredScene {
    fn cache_bytes(&self) -> usize {
        self.layers
            .iter()
            .map(|l| {
                l.image.heap_bytes()
                    + l.depth.heap_bytes()
                    + l.mask.heap_bytes()
                    + l.inpainted.heap_bytes()
                    + l.hole.heap_bytes()
            })
            .sum()
    }
}

impl CacheBytes for crate::stages::points::PointCloud {
    fn cache_bytes(&self) -> usize {
        use std::mem::size_of_val;
        size_of_val(self.positions.as_slice())
            + size_of_val(self.colours.as_slice())
            + size_of_val(self.alphas.as_slice())
            + size_of_val(self.tangent_u.as_slice())
            + size_of_val(self.tangent_v.as_slice())
            + size_of_val(self.source_depth.as_slice())
            + size_of_val(self.source_pixel.as_slice())
            + size_of_val(self.layer.as_slice())
            + size_of_val(self.inpainted.as_slice())
    }
}

impl CacheBytes for super::PreparedMotion {
    fn cache_bytes(&self) -> usize {
        self.field.flow.heap_bytes() + self.field.mask.heap_bytes() + self.motion_loop.heap_bytes()
    }
}

/// A stage cache seen without its output type: what [`trim`] needs of each.
pub(super) trait SpareEntries {
    /// `(bytes, tick)` of each entry nothing outside the cache holds (dropping it frees its
    /// memory), except the most recently used one.
    fn spare(&self) -> Vec<(usize, u64)>;
    /// Bytes of the entries something outside the cache also holds (the shown scene's).
    fn in_use_bytes(&self) -> usize;
    /// Drops the entry of `tick`.
    fn drop_tick(&mut self, tick: u64);
}

/// Monotonic use counter shared by every cache: the least recently used entry across stages is
/// the smallest tick.
static TICK: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

fn next_tick() -> u64 {
    TICK.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// Drops the least recently used spare entries of `caches` (across stages) until the spare
/// entries hold at most `budget` bytes; returns the bytes they hold after.
pub(super) fn trim(caches: &mut [&mut dyn SpareEntries], budget: usize) -> usize {
    let mut spare: Vec<(usize, u64, usize)> = caches
        .iter()
        .enumerate()
        .flat_map(|(i, c)| c.spare().into_iter().map(move |(b, t)| (b, t, i)))
        .collect();
    spare.sort_by_key(|s| s.1);
    let mut total: usize = spare.iter().map(|s| s.0).sum();
    for (bytes, tick, i) in spare {
        if total <= budget {
            break;
        }
        caches[i].drop_tick(tick);
        total -= bytes;
    }
    total
}

/// The spare budget next to `in_use` bytes of outputs the shown scene holds: one more state of
/// the same size (an undo finds every stage), at least [`MIN_SPARE_BYTES`].
pub fn spare_budget(in_use: usize) -> usize {
    in_use.max(MIN_SPARE_BYTES)
}

pub(super) struct Slot<T> {
    pub(super) key: u64,
    /// The canvas stage's inputs other than the layout; the layer inpainting's inputs other than
    /// the earlier layers it kept (0 for the other stages).
    pub(super) base: u64,
    pub(super) value: Arc<T>,
    /// The output's [`CacheBytes`].
    bytes: usize,
    /// When it was last used ([`next_tick`]).
    tick: u64,
}

/// One stage's cached outputs, least recently used first.
pub(super) struct StageCache<T> {
    entries: Vec<Slot<T>>,
}

impl<T> Default for StageCache<T> {
    fn default() -> Self {
        Self {
            entries: Vec::new(),
        }
    }
}

impl<T> StageCache<T> {
    /// The output for `key`, now the most recently used.
    pub(super) fn get(&mut self, key: u64) -> Option<Arc<T>> {
        let i = self.entries.iter().position(|s| s.key == key)?;
        let mut slot = self.entries.remove(i);
        slot.tick = next_tick();
        let value = slot.value.clone();
        self.entries.push(slot);
        Some(value)
    }

    /// The output for `key`, leaving the order as it is.
    pub(super) fn peek(&self, key: u64) -> Option<Arc<T>> {
        self.entries
            .iter()
            .find(|s| s.key == key)
            .map(|s| s.value.clone())
    }

    /// The most recently used entry that `keep` accepts: `(key, value)`.
    pub(super) fn newest(&self, keep: impl Fn(&Slot<T>) -> bool) -> Option<(u64, Arc<T>)> {
        self.entries
            .iter()
            .rev()
            .find(|s| keep(s))
            .map(|s| (s.key, s.value.clone()))
    }

    /// Stores `value` under `key`, dropping the least recently used entry beyond
    /// [`CACHE_ENTRIES`].
    pub(super) fn put(&mut self, key: u64, base: u64, value: Arc<T>)
    where
        T: CacheBytes,
    {
        self.entries.retain(|s| s.key != key);
        let bytes = value.cache_bytes();
        self.entries.push(Slot {
            key,
            base,
            value,
            bytes,
            tick: next_tick(),
        });
        if self.entries.len() > CACHE_ENTRIES {
            self.entries.remove(0);
        }
    }
}

impl<T> SpareEntries for StageCache<T> {
    fn in_use_bytes(&self) -> usize {
        self.entries
            .iter()
            .filter(|s| Arc::strong_count(&s.value) > 1)
            .map(|s| s.bytes)
            .sum()
    }

    fn spare(&self) -> Vec<(usize, u64)> {
        let n = self.entries.len();
        self.entries
            .iter()
            .take(n.saturating_sub(1))
            .filter(|s| Arc::strong_count(&s.value) == 1)
            .map(|s| (s.bytes, s.tick))
            .collect()
    }

    fn drop_tick(&mut self, tick: u64) {
        self.entries.retain(|s| s.tick != tick);
    }
}

#[derive(Default)]
pub(super) struct Stats {
    pub(super) runs: std::collections::BTreeMap<Stage, usize>,
    pub(super) seconds: std::collections::BTreeMap<Stage, f64>,
}

impl Stats {
    pub(super) fn ran(&mut self, stage: Stage, started: std::time::Instant) {
        *self.runs.entry(stage).or_insert(0) += 1;
        self.seconds.insert(stage, started.elapsed().as_secs_f64());
    }
}

/// `cache`'s output for `key`, or — unless `dry` — `run`'s, stored (with `base`, the slot's
/// [`Slot::base`]). `Err(stage)` only when `dry` and the stage would have to run.
pub(super) fn cached<T: CacheBytes>(
    cache: &mut StageCache<T>,
    stats: &mut Stats,
    stage: Stage,
    (key, base): (u64, u64),
    dry: bool,
    progress: &Progress,
    run: impl FnOnce(&Progress) -> Result<T>,
) -> Result<std::result::Result<Arc<T>, Stage>> {
    if let Some(v) = cache.get(key) {
        return Ok(Ok(v));
    }
    if dry {
        return Ok(Err(stage));
    }
    let started = std::time::Instant::now();
    progress.report(0.0, stage.name());
    let v = Arc::new(run(progress)?);
    stats.ran(stage, started);
    cache.put(key, base, v.clone());
    Ok(Ok(v))
}

/// Where a grown canvas came from: the key of the canvas it grew from, and where that one's
/// top-left pixel sits on it.
pub(super) type GrownCanvas = (u64, (usize, usize));

/// `list`'s value for `key`, now the most recently used, or `make`'s, remembered; `list` keeps
/// at most `limit` entries, least recently used first.
pub(super) fn remembered<T: Clone>(
    list: &mut Vec<(u64, T)>,
    key: u64,
    limit: usize,
    make: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let entry = match list.iter().position(|e| e.0 == key) {
        Some(i) => list.remove(i),
        None => (key, make()?),
    };
    let value = entry.1.clone();
    list.push(entry);
    if list.len() > limit {
        list.remove(0);
    }
    Ok(value)
}

/// A non-dry build's answer (a dry one alone can miss a stage).
pub(super) fn built<T>(answer: std::result::Result<T, Stage>) -> Result<T> {
    answer.map_err(|stage| {
        Error::invalid(format!(
            "internal: a build that is not dry missed the {} stage",
            stage.name()
        ))
    })
}

/// Hashes `parts` (serialised as JSON) together with the upstream key.
pub(super) fn key_of(upstream: u64, parts: &impl Serialize) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    upstream.hash(&mut h);
    serde_json::to_string(parts)
        .unwrap_or_default()
        .hash(&mut h);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Blob(usize);

    impl CacheBytes for Blob {
        fn cache_bytes(&self) -> usize {
            self.0
        }
    }

    #[test]
    fn trim_drops_the_least_recently_used_spare_entries_across_stages() {
        let mut a = StageCache::<Blob>::default();
        let mut b = StageCache::<Blob>::default();
        a.put(1, 0, Arc::new(Blob(100)));
        b.put(2, 0, Arc::new(Blob(50)));
        assert!(a.get(1).is_some()); // 1 is now used more recently than 2
        a.put(3, 0, Arc::new(Blob(30)));
        b.put(4, 0, Arc::new(Blob(70)));
        // The shown scene holds key 3's output; 4 is the newest of its stage.
        let held = a.peek(3).unwrap();
        assert_eq!(a.in_use_bytes(), 30);
        // Spare: a's 1 (100; 3 is held) and b's 2 (50; 4 is b's newest) = 150.
        let left = trim(&mut [&mut a, &mut b], 120);
        assert_eq!(
            left, 100,
            "the older of the two spare entries (key 2) goes first"
        );
        assert!(b.peek(2).is_none() && a.peek(1).is_some());
        let left = trim(&mut [&mut a, &mut b], 0);
        assert_eq!(left, 0);
        // The held entry and each stage's newest stay whatever the budget.
        assert!(a.peek(3).is_some() && b.peek(4).is_some() && a.peek(1).is_none());
        drop(held);
    }

    #[test]
    fn entries_beyond_the_count_go_whatever_their_size() {
        let mut a = StageCache::<Blob>::default();
        for k in 0..(CACHE_ENTRIES as u64 + 2) {
            a.put(k, 0, Arc::new(Blob(1)));
        }
        assert!(a.peek(0).is_none() && a.peek(1).is_none() && a.peek(2).is_some());
        assert_eq!(spare_budget(0), MIN_SPARE_BYTES);
        assert_eq!(spare_budget(1 << 40), 1 << 40);
    }
}
