//! Ward agglomerative clustering of the canvas disparity (algorithms.md §4), exact in 1-D.
//!
//! In one dimension the Ward clusters are intervals of the sorted values, and the cheapest
//! merge is always between two neighbouring intervals, so Ward runs on a fine weighted histogram
//! by merging adjacent bins through a priority queue: O(N) to build the histogram and
//! O(B log B) to merge its B bins. The merge cost of clusters `a` and `b` (Ward's linkage, the
//! increase of the within-cluster sum of squares) is
//! `Δ(a, b) = n_a·n_b/(n_a + n_b)·(μ_a − μ_b)²`.
//!
//! Resolution independence: every count scales with the number of pixels, so the merge order
//! does not depend on it, and the automatic criterion compares `Δ` with the *total* sum of
//! squares `T` (both scale with the pixel count): a boundary survives when merging across it
//! would add more than `τ·T`. The same scene at 640 px and 2560 px gets the same layers.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// One weighted atom of the clustering: a histogram bin (or, in tests, one sample).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WardAtom {
    /// Number of samples `n`.
    pub weight: f64,
    /// Sum of the samples' values.
    pub sum: f64,
    /// Sum of the squared values.
    pub sum_sq: f64,
    /// Smallest value in the atom.
    pub min: f64,
    /// Largest value in the atom.
    pub max: f64,
}

impl WardAtom {
    /// An atom holding one sample of value `v`.
    pub fn single(v: f64) -> Self {
        Self {
            weight: 1.0,
            sum: v,
            sum_sq: v * v,
            min: v,
            max: v,
        }
    }

    fn add(&mut self, v: f64) {
        self.weight += 1.0;
        self.sum += v;
        self.sum_sq += v * v;
        self.min = self.min.min(v);
        self.max = self.max.max(v);
    }

    /// Sum of squared deviations from the atom's own mean.
    fn within(&self) -> f64 {
        if self.weight > 0.0 {
            (self.sum_sq - self.sum * self.sum / self.weight).max(0.0)
        } else {
            0.0
        }
    }
}

/// Ward's merge cost `Δ(a, b) = n_a·n_b/(n_a + n_b)·(μ_a − μ_b)²` of two clusters given by
/// their weights `n` and value sums.
pub fn ward_cost(weight_a: f64, sum_a: f64, weight_b: f64, sum_b: f64) -> f64 {
    if weight_a <= 0.0 || weight_b <= 0.0 {
        return 0.0;
    }
    let d = sum_a / weight_a - sum_b / weight_b;
    weight_a * weight_b / (weight_a + weight_b) * d * d
}

/// The whole Ward dendrogram over atoms sorted by value: which boundary each merge removed, at
/// what cost.
#[derive(Clone, Debug)]
pub struct WardTree {
    atoms: Vec<WardAtom>,
    /// `(boundary, Δ)` in merge order; `boundary = j` separates atoms `< j` from atoms `≥ j`.
    merges: Vec<(usize, f64)>,
    /// Total sum of squares `T` of all samples around their mean.
    total: f64,
}

/// A heap entry: merging the cluster starting at `left` with the one starting at `right`.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    cost: f64,
    left: usize,
    right: usize,
    left_version: u32,
    right_version: u32,
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Candidate {
    /// Reversed so that `BinaryHeap` pops the cheapest merge first (ties: leftmost boundary).
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost
            .total_cmp(&self.cost)
            .then_with(|| other.right.cmp(&self.right))
    }
}

impl WardTree {
    /// Runs Ward's merges on `atoms` (sorted by value, non-overlapping, weights `> 0`) down to
    /// one cluster. O(B log B).
    pub fn build(atoms: Vec<WardAtom>) -> Self {
        let n = atoms.len();
        // A cluster is named by its first atom; it keeps that name when it absorbs its right
        // neighbour.
        let mut weight: Vec<f64> = atoms.iter().map(|a| a.weight).collect();
        let mut sum: Vec<f64> = atoms.iter().map(|a| a.sum).collect();
        let mut prev: Vec<Option<usize>> = (0..n).map(|i| i.checked_sub(1)).collect();
        let mut next: Vec<Option<usize>> = (0..n).map(|i| (i + 1 < n).then_some(i + 1)).collect();
        let mut alive = vec![true; n];
        let mut version = vec![0u32; n];
        let mut heap = BinaryHeap::with_capacity(n);
        let candidate =
            |l: usize, r: usize, weight: &[f64], sum: &[f64], version: &[u32]| Candidate {
                cost: ward_cost(weight[l], sum[l], weight[r], sum[r]),
                left: l,
                right: r,
                left_version: version[l],
                right_version: version[r],
            };
        for r in 1..n {
            heap.push(candidate(r - 1, r, &weight, &sum, &version));
        }
        let mut merges = Vec::with_capacity(n.saturating_sub(1));
        while let Some(c) = heap.pop() {
            let (l, r) = (c.left, c.right);
            if !alive[l]
                || !alive[r]
                || prev[r] != Some(l)
                || version[l] != c.left_version
                || version[r] != c.right_version
            {
                continue;
            }
            weight[l] += weight[r];
            sum[l] += sum[r];
            alive[r] = false;
            version[l] += 1;
            next[l] = next[r];
            if let Some(nr) = next[r] {
                prev[nr] = Some(l);
            }
            merges.push((r, c.cost));
            if let Some(pl) = prev[l] {
                heap.push(candidate(pl, l, &weight, &sum, &version));
            }
            if let Some(nl) = next[l] {
                heap.push(candidate(l, nl, &weight, &sum, &version));
            }
        }
        let total = merges.iter().map(|m| m.1).sum::<f64>()
            + atoms.iter().map(WardAtom::within).sum::<f64>();
        Self {
            atoms,
            merges,
            total,
        }
    }

    /// The atoms, sorted by value.
    pub fn atoms(&self) -> &[WardAtom] {
        &self.atoms
    }

    /// Merge costs `Δ_k` in merge order (non-decreasing: Ward's linkage is monotone).
    pub fn costs(&self) -> impl Iterator<Item = f64> + '_ {
        self.merges.iter().map(|m| m.1)
    }

    /// Total sum of squares `T` around the mean (within the atoms plus every merge's cost).
    pub fn total(&self) -> f64 {
        self.total
    }

    /// The number of clusters `L = 1 + #{k : Δ_k > τ·T}` for the resolution-independent
    /// criterion `τ = relative_cost` (the dendrogram cut at height `τ·T`). 1 when `T = 0`.
    pub fn count_for_relative_cost(&self, relative_cost: f64) -> usize {
        if self.total <= 0.0 || !self.total.is_finite() {
            return 1;
        }
        let limit = relative_cost * self.total;
        1 + self.merges.iter().filter(|m| m.1 > limit).count()
    }

    /// The boundaries (sorted atom indices `j`, each separating atoms `< j` from `≥ j`) of the
    /// partition into `clusters` clusters (clamped to `[1, B]`): those removed by the last
    /// `clusters − 1` merges.
    pub fn boundaries(&self, clusters: usize) -> Vec<usize> {
        let keep = clusters.clamp(1, self.atoms.len().max(1)) - 1;
        let mut b: Vec<usize> = self.merges[self.merges.len() - keep..]
            .iter()
            .map(|m| m.0)
            .collect();
        b.sort_unstable();
        b
    }
}

/// Builds the disparity histogram of `depth` (disparity `δ = 1/Z` of every finite `Z > 0`)
/// with `bins` equal bins over `[min δ, max δ]`; empty bins are dropped. `None` when no depth is
/// usable.
pub fn disparity_atoms(depth: &[f32], bins: usize) -> Option<Vec<WardAtom>> {
    let bins = bins.max(1);
    let disparity = |z: f32| (z.is_finite() && z > 0.0).then(|| 1.0 / f64::from(z));
    let (lo, hi) = depth
        .iter()
        .filter_map(|&z| disparity(z))
        .fold(None, |acc: Option<(f64, f64)>, d| {
            Some(acc.map_or((d, d), |(lo, hi)| (lo.min(d), hi.max(d))))
        })?;
    let empty = WardAtom {
        weight: 0.0,
        sum: 0.0,
        sum_sq: 0.0,
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
    };
    let mut hist = vec![empty; bins];
    let scale = if hi > lo {
        bins as f64 / (hi - lo)
    } else {
        0.0
    };
    for d in depth.iter().filter_map(|&z| disparity(z)) {
        let b = (((d - lo) * scale) as usize).min(bins - 1);
        hist[b].add(d);
    }
    Some(hist.into_iter().filter(|a| a.weight > 0.0).collect())
}

/// Depth thresholds `d_1 < … < d_{L+1}` of the partition of the sorted `atoms` at
/// `boundaries` (each `j` separates atoms `< j` from atoms `≥ j`). `d_1` is the smallest depth
/// and `d_{L+1}` the largest; an interior threshold lies halfway (in disparity) across the gap
/// between two neighbouring clusters, rounded up to the next `f32` so that every sample of the
/// nearer cluster is `< d_i` and every sample of the farther one `≥ d_i` (the layers are
/// half-open, `d_i ≤ Z < d_{i+1}`). Empty when there are no atoms.
pub fn thresholds_from_boundaries(atoms: &[WardAtom], boundaries: &[usize]) -> Vec<f32> {
    let (Some(first), Some(last)) = (atoms.first(), atoms.last()) else {
        return Vec::new();
    };
    let depth_up = |z: f64| {
        let f = z as f32;
        if f64::from(f) < z { f.next_up() } else { f }
    };
    let mut t: Vec<f32> = boundaries
        .iter()
        .filter(|&&j| j > 0 && j < atoms.len())
        .map(|&j| depth_up(2.0 / (atoms[j - 1].max + atoms[j].min)))
        .collect();
    t.push((1.0 / last.max) as f32);
    t.push(depth_up(1.0 / first.min));
    t.sort_by(f32::total_cmp);
    t
}

/// Depth thresholds of Ward's partition of `tree` into `clusters` clusters (see
/// [`thresholds_from_boundaries`]).
pub fn thresholds_from_tree(tree: &WardTree, clusters: usize) -> Vec<f32> {
    thresholds_from_boundaries(tree.atoms(), &tree.boundaries(clusters))
}

/// The exact minimum of Ward's objective: for every `k ≤ K`, the partition of the sorted atoms
/// into `k` intervals with the smallest within-cluster sum of squares `W*(k)` (optimal 1-D
/// k-means; Wang & Song 2011, "Ckmeans.1d.dp"). Dynamic programming over the histogram,
/// `D_k(j) = min_i D_{k−1}(i) + SS(i..j)`, with divide-and-conquer over the split index
/// (monotone, since `SS` satisfies the quadrangle inequality): O(K·B log B).
///
/// Greedy Ward freezes early merges made on histogram noise, so on a continuous disparity
/// distribution its boundaries move with the resolution; the optimum does not.
#[derive(Clone, Debug)]
pub struct OptimalPartitions {
    /// `W*(k)` for `k = 1..=K` (index `k − 1`), including the atoms' own spread.
    within: Vec<f64>,
    /// Sorted boundaries of the optimal `k`-partition (index `k − 1`).
    boundaries: Vec<Vec<usize>>,
}

impl OptimalPartitions {
    /// Solves for every `k` from 1 to `max_clusters` (clamped to `[1, B]`).
    pub fn build(atoms: &[WardAtom], max_clusters: usize) -> Self {
        let b = atoms.len();
        if b == 0 {
            return Self {
                within: vec![0.0],
                boundaries: vec![Vec::new()],
            };
        }
        let kmax = max_clusters.clamp(1, b);
        // Prefix sums of values centred on the mean, for conditioning.
        let (wt, st) = atoms
            .iter()
            .fold((0.0, 0.0), |(w, s), a| (w + a.weight, s + a.sum));
        let mean = st / wt;
        // Atoms i..j (exclusive) are treated as points at their means: their sum of squares is
        // `Σ s_a²/n_a − S²/N` on centred sums, and the spread inside the atoms is the
        // constant `atoms_within`.
        let mut pw = vec![0.0f64; b + 1];
        let mut ps = vec![0.0f64; b + 1];
        let mut pb = vec![0.0f64; b + 1];
        for (i, a) in atoms.iter().enumerate() {
            let s = a.sum - a.weight * mean;
            pw[i + 1] = pw[i] + a.weight;
            ps[i + 1] = ps[i] + s;
            pb[i + 1] = pb[i]
                + if a.weight > 0.0 {
                    s * s / a.weight
                } else {
                    0.0
                };
        }
        let atoms_within: f64 = atoms.iter().map(WardAtom::within).sum();
        let cost = |i: usize, j: usize| -> f64 {
            let w = pw[j] - pw[i];
            if w <= 0.0 {
                return 0.0;
            }
            let s = ps[j] - ps[i];
            ((pb[j] - pb[i]) - s * s / w).max(0.0)
        };
        let mut dp: Vec<Vec<f64>> = Vec::with_capacity(kmax);
        let mut arg: Vec<Vec<usize>> = Vec::with_capacity(kmax);
        dp.push((0..=b).map(|j| cost(0, j)).collect());
        arg.push(vec![0; b + 1]);
        for k in 2..=kmax {
            let prev = &dp[k - 2];
            let mut cur = vec![f64::INFINITY; b + 1];
            let mut at = vec![0usize; b + 1];
            // Divide and conquer over j in [k, b] with split indices in [k − 1, b − 1].
            let mut stack = vec![(k, b, k - 1, b - 1)];
            while let Some((jlo, jhi, olo, ohi)) = stack.pop() {
                if jlo > jhi {
                    continue;
                }
                let mid = (jlo + jhi) / 2;
                let mut best = (f64::INFINITY, olo);
                for (i, &before) in prev.iter().enumerate().take(ohi.min(mid - 1) + 1).skip(olo) {
                    let c = before + cost(i, mid);
                    if c < best.0 {
                        best = (c, i);
                    }
                }
                cur[mid] = best.0;
                at[mid] = best.1;
                if mid > jlo {
                    stack.push((jlo, mid - 1, olo, best.1));
                }
                stack.push((mid + 1, jhi, best.1, ohi));
            }
            dp.push(cur);
            arg.push(at);
        }
        let within = dp.iter().map(|d| d[b] + atoms_within).collect();
        let boundaries = (1..=kmax)
            .map(|k| {
                let mut cuts = Vec::with_capacity(k - 1);
                let mut j = b;
                for kk in (2..=k).rev() {
                    j = arg[kk - 1][j];
                    cuts.push(j);
                }
                cuts.reverse();
                cuts
            })
            .collect();
        Self { within, boundaries }
    }

    /// The largest `k` solved for.
    pub fn max_clusters(&self) -> usize {
        self.within.len()
    }

    /// `W*(k)`, the smallest within-cluster sum of squares of a `k`-partition; `None` beyond
    /// the solved range.
    pub fn within(&self, k: usize) -> Option<f64> {
        k.checked_sub(1).and_then(|i| self.within.get(i).copied())
    }

    /// Total sum of squares `T = W*(1)`.
    pub fn total(&self) -> f64 {
        self.within[0]
    }

    /// The resolution-independent count: the smallest `L` whose next split would reduce the
    /// within-cluster sum of squares by no more than `τ·T`, i.e. `W*(L) − W*(L+1) ≤ τ·T`
    /// (the solved maximum when every split gains more). 1 when `T = 0`.
    pub fn count_for_relative_gain(&self, relative_gain: f64) -> usize {
        let t = self.total();
        if t <= 0.0 || !t.is_finite() {
            return 1;
        }
        (1..self.max_clusters())
            .find(|&l| self.within[l - 1] - self.within[l] <= relative_gain * t)
            .unwrap_or(self.max_clusters())
    }

    /// Sorted boundaries of the optimal partition into `k` clusters (clamped to the solved
    /// range).
    pub fn boundaries(&self, k: usize) -> &[usize] {
        &self.boundaries[k.clamp(1, self.max_clusters()) - 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(seed: &mut u64) -> u64 {
        *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn uniform(seed: &mut u64) -> f64 {
        (rng(seed) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Textbook Ward on raw samples: every step merges the cheapest pair of *any* two clusters
    /// (O(n³)). Returns, for every cluster count `k` from `n` down to 1, the cluster label of
    /// every sample.
    fn brute_force_ward(values: &[f64]) -> Vec<Vec<usize>> {
        let mut clusters: Vec<Vec<usize>> = (0..values.len()).map(|i| vec![i]).collect();
        let stats = |c: &Vec<usize>| (c.len() as f64, c.iter().map(|&i| values[i]).sum::<f64>());
        let label = |clusters: &Vec<Vec<usize>>| {
            let mut l = vec![0; values.len()];
            for (k, c) in clusters.iter().enumerate() {
                for &i in c {
                    l[i] = k;
                }
            }
            l
        };
        let mut out = vec![label(&clusters)];
        while clusters.len() > 1 {
            let mut best = (f64::INFINITY, 0, 0);
            for a in 0..clusters.len() {
                for b in a + 1..clusters.len() {
                    let (wa, sa) = stats(&clusters[a]);
                    let (wb, sb) = stats(&clusters[b]);
                    let c = ward_cost(wa, sa, wb, sb);
                    if c < best.0 {
                        best = (c, a, b);
                    }
                }
            }
            let merged = clusters.remove(best.2);
            clusters[best.1].extend(merged);
            out.push(label(&clusters));
        }
        out
    }

    /// True when two labelings describe the same partition.
    fn same_partition(a: &[usize], b: &[usize]) -> bool {
        (0..a.len()).all(|i| (0..a.len()).all(|j| (a[i] == a[j]) == (b[i] == b[j])))
    }

    /// Labels of samples under the partition of sorted distinct `levels` at `boundaries`.
    fn labels_from_boundaries(values: &[f64], levels: &[f64], boundaries: &[usize]) -> Vec<usize> {
        values
            .iter()
            .map(|v| {
                let j = levels
                    .iter()
                    .position(|l| l == v)
                    .expect("value is a level");
                boundaries.iter().filter(|&&b| b <= j).count()
            })
            .collect()
    }

    #[test]
    fn ward_cost_known_answers() {
        // Two single samples 0 and 1: Δ = ½·1 = 0.5.
        assert_eq!(ward_cost(1.0, 0.0, 1.0, 1.0), 0.5);
        // {0, 0} and {3}: Δ = 2·1/3·3² = 6.
        assert!((ward_cost(2.0, 0.0, 1.0, 3.0) - 6.0).abs() < 1e-12);
        // Extremes: equal means cost nothing; an empty cluster costs nothing.
        assert_eq!(ward_cost(5.0, 10.0, 3.0, 6.0), 0.0);
        assert_eq!(ward_cost(0.0, 0.0, 3.0, 6.0), 0.0);
        // Huge weights stay finite.
        assert!(ward_cost(1e15, 1e15, 1e15, 0.0).is_finite());
    }

    #[test]
    fn adjacent_merges_equal_brute_force_ward_on_random_samples() {
        let mut seed = 42;
        for case in 0..200 {
            // A few distinct random levels, each drawn several times (duplicates are merged at
            // zero cost first by both methods).
            let distinct = 2 + (rng(&mut seed) % 10) as usize;
            let mut levels: Vec<f64> = (0..distinct).map(|_| uniform(&mut seed)).collect();
            levels.sort_by(f64::total_cmp);
            levels.dedup();
            let n = 3 + (rng(&mut seed) % 25) as usize;
            let mut values: Vec<f64> = (0..n)
                .map(|_| levels[(rng(&mut seed) % levels.len() as u64) as usize])
                .collect();
            values.sort_by(f64::total_cmp);
            let used: Vec<f64> = {
                let mut u = values.clone();
                u.dedup();
                u
            };
            // Atoms: the distinct values with their multiplicities.
            let atoms: Vec<WardAtom> = used
                .iter()
                .map(|&v| {
                    let mut a = WardAtom::single(v);
                    for _ in 1..values.iter().filter(|&&x| x == v).count() {
                        a.add(v);
                    }
                    a
                })
                .collect();
            let tree = WardTree::build(atoms);
            let brute = brute_force_ward(&values);
            for k in 1..=used.len() {
                let want = &brute[values.len() - k];
                let got = labels_from_boundaries(&values, &used, &tree.boundaries(k));
                assert!(
                    same_partition(&got, want),
                    "case {case}, {k} clusters: {values:?}\n got {got:?}\nwant {want:?}"
                );
            }
            // Costs are non-decreasing and sum (with the zero-cost duplicate merges) to T.
            let costs: Vec<f64> = tree.costs().collect();
            assert!(costs.windows(2).all(|w| w[1] >= w[0] - 1e-12), "{costs:?}");
            let mean = values.iter().sum::<f64>() / n as f64;
            let t: f64 = values.iter().map(|v| (v - mean) * (v - mean)).sum();
            assert!((tree.total() - t).abs() < 1e-9 * t.max(1.0));
        }
    }

    #[test]
    fn histogram_path_equals_brute_force_when_bins_separate_values() {
        let mut seed = 9;
        for case in 0..60 {
            // Depths whose disparities are distinct integers out of 0..1000 shifted by 10: with
            // 4096 bins over the range every distinct value gets its own bin.
            let distinct = 2 + (rng(&mut seed) % 8) as usize;
            let mut integers: Vec<u64> = (0..distinct).map(|_| rng(&mut seed) % 1000).collect();
            integers.sort_unstable();
            integers.dedup();
            let levels: Vec<f64> = integers
                .iter()
                .map(|&i| 10.0 + i as f64 + 0.25 * uniform(&mut seed))
                .collect();
            let n = 4 + (rng(&mut seed) % 30) as usize;
            let disparities: Vec<f64> = (0..n)
                .map(|_| levels[(rng(&mut seed) % levels.len() as u64) as usize])
                .collect();
            let depth: Vec<f32> = disparities.iter().map(|d| (1.0 / d) as f32).collect();
            // The brute force sees the disparities the histogram sees.
            let values: Vec<f64> = depth.iter().map(|&z| 1.0 / f64::from(z)).collect();
            let atoms = disparity_atoms(&depth, 4096).expect("finite depth");
            let mut used = values.clone();
            used.sort_by(f64::total_cmp);
            used.dedup();
            assert_eq!(
                atoms.len(),
                used.len(),
                "case {case}: bins must separate values"
            );
            let tree = WardTree::build(atoms);
            let brute = brute_force_ward(&values);
            for k in 1..=used.len() {
                let want = &brute[values.len() - k];
                // Partition by thresholds, as the layers do: label = #{interior d ≤ Z}.
                let t = thresholds_from_tree(&tree, k);
                assert_eq!(t.len(), k + 1);
                let got: Vec<usize> = depth
                    .iter()
                    .map(|&z| t[1..k].iter().filter(|&&d| d <= z).count())
                    .collect();
                assert!(same_partition(&got, want), "case {case}, k = {k}");
                // Every cluster is non-empty under the half-open rule.
                for l in 0..k {
                    assert!(got.contains(&l), "case {case}, k = {k}: layer {l} empty");
                }
            }
        }
    }

    /// Smallest within-cluster sum of squares over *every* partition of the sorted atoms into
    /// `k` intervals (exhaustive), with the boundaries that reach it.
    fn brute_force_optimum(atoms: &[WardAtom], k: usize) -> (f64, Vec<usize>) {
        let b = atoms.len();
        let ss = |i: usize, j: usize| {
            let (w, s, q) = atoms[i..j].iter().fold((0.0, 0.0, 0.0), |(w, s, q), a| {
                (w + a.weight, s + a.sum, q + a.sum_sq)
            });
            q - s * s / w
        };
        let mut best = (f64::INFINITY, Vec::new());
        // Every (k − 1)-subset of the b − 1 cut positions, as a bit mask.
        for mask in 0u32..(1 << (b - 1)) {
            if mask.count_ones() as usize != k - 1 {
                continue;
            }
            let cuts: Vec<usize> = (1..b).filter(|j| mask & (1 << (j - 1)) != 0).collect();
            let mut edges = vec![0];
            edges.extend(&cuts);
            edges.push(b);
            let total: f64 = edges.windows(2).map(|e| ss(e[0], e[1])).sum();
            if total < best.0 - 1e-12 {
                best = (total, cuts);
            }
        }
        best
    }

    #[test]
    fn optimal_partitions_equal_exhaustive_search() {
        let mut seed = 3;
        for case in 0..150 {
            let b = 1 + (rng(&mut seed) % 11) as usize;
            let mut values: Vec<f64> = (0..b).map(|_| uniform(&mut seed)).collect();
            values.sort_by(f64::total_cmp);
            values.dedup();
            // Random weights, and some atoms with an internal spread.
            let atoms: Vec<WardAtom> = values
                .iter()
                .map(|&v| {
                    let mut a = WardAtom::single(v);
                    for _ in 0..rng(&mut seed) % 5 {
                        a.add(v + 1e-3 * uniform(&mut seed));
                    }
                    a
                })
                .collect();
            let solved = OptimalPartitions::build(&atoms, 6);
            let ward = WardTree::build(atoms.clone());
            assert!(
                (solved.total() - ward.total()).abs() < 1e-9,
                "case {case}: T"
            );
            for k in 1..=solved.max_clusters() {
                let (want, cuts) = brute_force_optimum(&atoms, k);
                let got = solved.within(k).expect("solved");
                assert!(
                    (got - want).abs() < 1e-9,
                    "case {case}, k = {k}: {got} vs {want}"
                );
                assert_eq!(solved.boundaries(k), &cuts[..], "case {case}, k = {k}");
                // Greedy Ward never beats the optimum.
                let ward_ss: f64 = {
                    let mut e = vec![0];
                    e.extend(ward.boundaries(k));
                    e.push(atoms.len());
                    e.windows(2)
                        .map(|w| {
                            let (n, s, q) =
                                atoms[w[0]..w[1]].iter().fold((0.0, 0.0, 0.0), |acc, a| {
                                    (acc.0 + a.weight, acc.1 + a.sum, acc.2 + a.sum_sq)
                                });
                            q - s * s / n
                        })
                        .sum()
                };
                assert!(got <= ward_ss + 1e-9, "case {case}, k = {k}");
            }
        }
    }

    #[test]
    fn relative_gain_criterion_known_answers() {
        // Three modes of 20 samples at 0, 1 and 10: splitting off 10 gains almost all of T,
        // splitting 0 from 1 the rest.
        let mut atoms = Vec::new();
        for centre in [0.0, 1.0, 10.0] {
            let mut a = WardAtom::single(centre);
            for _ in 1..20 {
                a.add(centre);
            }
            atoms.push(a);
        }
        let solved = OptimalPartitions::build(&atoms, 3);
        // T = Σ 20·(c − 11/3)² = 20·(13.444 + 7.111 + 40.111) = 1213.33.
        let t = 20.0 * ((11.0f64 / 3.0).powi(2) + (8.0f64 / 3.0).powi(2) + (19.0f64 / 3.0).powi(2));
        assert!((solved.total() - t).abs() < 1e-9);
        // W*(2) = 20·½² + 20·½² = 10 ({0, 1} | {10}); W*(3) = 0.
        assert!((solved.within(2).expect("k = 2") - 10.0).abs() < 1e-9);
        assert!(solved.within(3).expect("k = 3").abs() < 1e-9);
        assert_eq!(solved.boundaries(2), &[2]);
        // Gains: (T − 10)/T ≈ 0.9918 for the 2nd cluster, 10/T ≈ 0.0082 for the 3rd.
        assert_eq!(solved.count_for_relative_gain(0.5), 2);
        assert_eq!(solved.count_for_relative_gain(0.01), 2);
        assert_eq!(solved.count_for_relative_gain(0.008), 3);
        assert_eq!(solved.count_for_relative_gain(1.0), 1);
        // Scaling every weight (a larger image) changes nothing.
        let scaled: Vec<WardAtom> = atoms
            .iter()
            .map(|a| WardAtom {
                weight: a.weight * 16.0,
                sum: a.sum * 16.0,
                sum_sq: a.sum_sq * 16.0,
                ..*a
            })
            .collect();
        let big = OptimalPartitions::build(&scaled, 3);
        for tau in [0.0, 0.008, 0.01, 0.5, 1.0] {
            assert_eq!(
                big.count_for_relative_gain(tau),
                solved.count_for_relative_gain(tau)
            );
        }
        // Extremes: no atoms, one atom, more clusters than atoms.
        assert_eq!(OptimalPartitions::build(&[], 4).max_clusters(), 1);
        let one = OptimalPartitions::build(&atoms[..1], 8);
        assert_eq!(one.max_clusters(), 1);
        assert_eq!(one.count_for_relative_gain(0.0), 1);
        assert!(one.boundaries(5).is_empty());
        assert_eq!(solved.boundaries(99), &[1, 2]);
    }

    #[test]
    fn relative_cost_criterion_known_answers() {
        // Two tight, equal modes at 0 and 1 with tiny jitter: the final merge costs almost all
        // of T, every other merge almost nothing → 2 clusters for any τ in (0.001, 0.99).
        // Irregular jitter, so that no two merges tie.
        let mut seed = 5;
        let mut jitter: Vec<f64> = (0..100).map(|_| uniform(&mut seed) * 5e-3).collect();
        jitter[..50].sort_by(f64::total_cmp);
        jitter[50..].sort_by(f64::total_cmp);
        let atoms: Vec<WardAtom> = (0..100)
            .map(|i| WardAtom::single(if i < 50 { 0.0 } else { 1.0 } + jitter[i]))
            .collect();
        let tree = WardTree::build(atoms);
        for tau in [0.01, 0.1, 0.5, 0.9] {
            assert_eq!(tree.count_for_relative_cost(tau), 2, "τ = {tau}");
        }
        // τ ≥ 1: nothing costs more than T → one cluster; τ = 0: every positive merge survives.
        assert_eq!(tree.count_for_relative_cost(1.0), 1);
        assert_eq!(tree.count_for_relative_cost(0.0), 100);
        // Weights scaled by 1000 (a 1000× larger image) give the same count and boundaries.
        let scaled: Vec<WardAtom> = tree
            .atoms()
            .iter()
            .map(|a| WardAtom {
                weight: a.weight * 1000.0,
                sum: a.sum * 1000.0,
                sum_sq: a.sum_sq * 1000.0,
                ..*a
            })
            .collect();
        let big = WardTree::build(scaled);
        for tau in [0.0, 0.01, 0.3, 1.0] {
            assert_eq!(
                big.count_for_relative_cost(tau),
                tree.count_for_relative_cost(tau)
            );
        }
        assert_eq!(big.boundaries(2), tree.boundaries(2));
        assert_eq!(big.boundaries(7), tree.boundaries(7));
    }

    #[test]
    fn extremes_single_value_no_value_and_nan() {
        // One distinct depth: one atom, one cluster, thresholds [Z, Z].
        let atoms = disparity_atoms(&[4.0; 10], 4096).expect("finite");
        assert_eq!(atoms.len(), 1);
        let tree = WardTree::build(atoms);
        assert_eq!(tree.total(), 0.0);
        assert_eq!(tree.count_for_relative_cost(0.05), 1);
        assert_eq!(thresholds_from_tree(&tree, 3), vec![4.0, 4.0]);
        // Nothing usable.
        assert!(disparity_atoms(&[f32::NAN, 0.0, -1.0, f32::INFINITY], 64).is_none());
        assert!(disparity_atoms(&[], 64).is_none());
        // NaN is ignored, not binned.
        let atoms = disparity_atoms(&[1.0, f32::NAN, 2.0], 64).expect("finite");
        assert_eq!(atoms.iter().map(|a| a.weight).sum::<f64>(), 2.0);
        // Empty tree.
        let tree = WardTree::build(Vec::new());
        assert!(thresholds_from_tree(&tree, 2).is_empty());
        assert!(tree.boundaries(3).is_empty());
        // Huge and tiny depths stay finite and ordered.
        let atoms = disparity_atoms(&[1e-30, 1e30, 1.0], 16).expect("finite");
        let tree = WardTree::build(atoms);
        let t = thresholds_from_tree(&tree, 3);
        assert!(t.iter().all(|v| v.is_finite() || *v == f32::INFINITY));
        assert!(t.windows(2).all(|w| w[0] <= w[1]), "{t:?}");
    }
}
