//! The occurrence penalty (Kaspar et al. 2015): how often each part of the source is already
//! copied, and what a candidate pays for it.

use super::cost::{Field, Problem};
use super::{NONE, OCCURRENCE_FLOOR, OCCURRENCE_RELATIVE};

/// How often each part of the source is already copied, for the occurrence penalty (Kaspar et
/// al. 2015), kept per cell of `side × side` pixels (`side` the patch side).
///
/// A cell's *uses* are the target patches whose source centre lies in it divided by its area:
/// a region copied once, as a whole, is used once. Its *fair share* is
/// `max(1, targets / valid sources)`. A candidate pays
/// `occurrence · patch area · (excess + memory)` for its cell, `excess = max(0, uses − fair)`,
/// capped by [`Occurrence::charge`] relative to its own matching cost.
///
/// Every pass recounts the cells from the field; inside a band (processed in scan order) each
/// change of match moves one count at once, so a band never sends more than its share to one
/// spot. Bands that run at once start from the same counts and may all rush to the same best spot,
/// so a pass runs the bands in [`OCCURRENCE_PHASES`](super::OCCURRENCE_PHASES) phases (band `b` in
/// phase `b mod phases`), recounting between them: only the bands of one phase herd together.
/// `memory`, the excess of earlier passes halved per pass, keeps a spot that was crowded from
/// drawing the crowd straight back.
pub(super) struct Occurrence {
    /// Cost per patch pixel and excess use; 0 = off.
    pub(super) per_use: f32,
    /// [`OCCURRENCE_FLOOR`] for the whole patch.
    pub(super) floor: f32,
    pub(super) side: usize,
    /// Cells per row.
    pub(super) cw: usize,
    pub(super) fair: f32,
    /// Target centres per cell at the start of the pass.
    pub(super) counts: Vec<f32>,
    /// Decayed excess of earlier passes, per cell.
    pub(super) memory: Vec<f32>,
}

impl Occurrence {
    pub(super) fn new(problem: &Problem) -> Occurrence {
        let side = 2 * problem.r + 1;
        let (cw, ch) = (problem.w.div_ceil(side), problem.h.div_ceil(side));
        let per_use = problem.occurrence * problem.patch_pixels();
        let cells = if per_use > 0.0 { cw * ch } else { 0 };
        Occurrence {
            per_use,
            floor: OCCURRENCE_FLOOR * problem.patch_pixels(),
            side,
            cw,
            fair: 1.0,
            counts: vec![0.0; cells],
            memory: vec![0.0; cells],
        }
    }

    pub(super) fn enabled(&self) -> bool {
        !self.counts.is_empty()
    }

    #[inline]
    pub(super) fn cell(&self, s: usize, w: usize) -> usize {
        (s / w / self.side) * self.cw + (s % w) / self.side
    }

    pub(super) fn area(&self) -> f32 {
        (self.side * self.side) as f32
    }

    /// Starts a pass: adds the last count's excess to the memory, then recounts the cells from
    /// the field.
    pub(super) fn recount(&mut self, problem: &Problem, field: &Field) {
        self.remember();
        self.recount_sources(problem, field.nnf.iter().copied());
    }

    /// Halves the memory and adds the current excess to it.
    pub(super) fn remember(&mut self) {
        let area = self.area();
        for (m, &c) in self.memory.iter_mut().zip(&self.counts) {
            *m = 0.5 * (*m + (c / area - self.fair).max(0.0));
        }
    }

    /// Recounts the cells from the source centres (`NONE` = none).
    pub(super) fn recount_sources(
        &mut self,
        problem: &Problem,
        sources: impl IntoIterator<Item = u32>,
    ) {
        if !self.enabled() {
            return;
        }
        self.counts.iter_mut().for_each(|c| *c = 0.0);
        let mut targets = 0usize;
        for s in sources {
            if s != NONE {
                let cell = self.cell(s as usize, problem.w);
                self.counts[cell] += 1.0;
                targets += 1;
            }
        }
        self.fair = (targets as f32 / problem.valid_list.len().max(1) as f32).max(1.0);
    }

    /// The penalty of source centre `s`, with `delta` the changes this band made to the counts.
    #[inline]
    pub(super) fn penalty(&self, s: usize, w: usize, delta: &[f32]) -> f32 {
        if !self.enabled() {
            return 0.0;
        }
        let cell = self.cell(s, w);
        let uses = (self.counts[cell] + delta[cell]) / self.area();
        self.per_use * ((uses - self.fair).max(0.0) + self.memory[cell])
    }

    /// What a candidate with matching cost `cost` pays of its `penalty`: at most
    /// `OCCURRENCE_RELATIVE · cost + floor`. An uncrowded alternative of cost `c'` then wins
    /// over a crowded candidate of cost `c` only when `c' < c + charge ≤ (1 + relative) · c +
    /// floor`: the penalty spreads the fill over near-equal sources but never trades a good
    /// match for a clearly worse one. Nondecreasing in `cost`.
    #[inline]
    pub(super) fn charge(&self, penalty: f32, cost: f32) -> f32 {
        penalty.min(OCCURRENCE_RELATIVE * cost.max(0.0) + self.floor)
    }

    /// The least [`Occurrence::charge`] of `penalty` whatever the cost: a bound for the early
    /// exit of the patch distance.
    #[inline]
    pub(super) fn least_charge(&self, penalty: f32) -> f32 {
        penalty.min(self.floor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One 3×3-pixel cell used `uses` times over, with `per_use` 1 and a floor of 0.01.
    fn crowded(uses: f32) -> Occurrence {
        Occurrence {
            per_use: 1.0,
            floor: 0.01,
            side: 3,
            cw: 1,
            fair: 1.0,
            counts: vec![uses * 9.0],
            memory: vec![0.0],
        }
    }

    #[test]
    fn the_charge_is_the_excess_capped_by_the_matching_cost() {
        let occ = crowded(5.0);
        let delta = [0.0f32];
        // Used 5 times against a fair share of 1: a penalty of 4.
        let penalty = occ.penalty(0, 3, &delta);
        assert!((penalty - 4.0).abs() < 1e-6, "{penalty}");
        // A cheap match pays at most its cost (OCCURRENCE_RELATIVE = 1) plus the floor ...
        assert!((occ.charge(penalty, 0.5) - (0.5 * OCCURRENCE_RELATIVE + 0.01)).abs() < 1e-6);
        // ... so an uncrowded rival replaces it only below twice its cost: a rival of 0.9
        // does, a rival of 1.1 does not.
        let crowded_total = 0.5 + occ.charge(penalty, 0.5);
        assert!(
            0.9 < crowded_total && crowded_total < 1.1,
            "{crowded_total}"
        );
        // A costly match pays the whole penalty.
        assert_eq!(occ.charge(penalty, 100.0), penalty);
        // Uncrowded: nothing to pay; the floor bounds the early exit.
        let fair = crowded(1.0);
        assert_eq!(fair.penalty(0, 3, &delta), 0.0);
        assert_eq!(occ.least_charge(penalty), 0.01);
    }
}
