//! The stage caches: each stage's recent outputs keyed by a hash of its parameters and the key
//! of the stage before it ([`key_of`]), least recently used first, and the run statistics.

use super::Stage;
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::Serialize;
use std::hash::{Hash, Hasher};
use std::sync::Arc;

/// How many outputs each stage keeps, keyed by the stage's inputs: returning to an earlier state
/// (undo, redo, deleting the key just added, switching a count back) finds every stage cached.
/// The editor's whole session on a 1280×800 photo (`makeit4d bench editor`, which fills these
/// caches) peaks at 2.3 GiB resident; a one-shot build of the same photo at about 350 MiB.
pub const CACHE_ENTRIES: usize = 4;

pub(super) struct Slot<T> {
    pub(super) key: u64,
    /// The canvas stage's inputs other than the layout; the layer inpainting's inputs other than
    /// the earlier layers it kept (0 for the other stages).
    pub(super) base: u64,
    pub(super) value: Arc<T>,
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
        let slot = self.entries.remove(i);
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
    pub(super) fn put(&mut self, key: u64, base: u64, value: Arc<T>) {
        self.entries.retain(|s| s.key != key);
        self.entries.push(Slot { key, base, value });
        if self.entries.len() > CACHE_ENTRIES {
            self.entries.remove(0);
        }
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
pub(super) fn cached<T>(
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
