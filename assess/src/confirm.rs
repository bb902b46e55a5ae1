//! §3 Temporal confirmation: a ring of the last M raw states with per-state counts.

use crate::area::AreaId;

/// Confirms raw states by strict majority over the last M pushed frames.
///
/// States are coded `0..n` for areas and `n` for ∅. The divisor is always M, also while fewer
/// than M frames have been pushed. O(N) per push for N areas (a scan of N + 1 counts), O(1) in
/// the length of the trial; no allocation after construction.
#[derive(Debug, Clone)]
pub(crate) struct Confirmer {
    ring: Vec<u16>,
    next: usize,
    len: usize,
    counts: Vec<u32>,
    n_areas: usize,
    state: Option<AreaId>,
}

impl Confirmer {
    pub(crate) fn new(n_areas: usize, m: usize) -> Self {
        Self {
            ring: vec![0; m],
            next: 0,
            len: 0,
            counts: vec![0; n_areas + 1],
            n_areas,
            state: None,
        }
    }

    /// The confirmed state; ∅ before the first confirmation.
    pub(crate) fn state(&self) -> Option<AreaId> {
        self.state
    }

    /// Push one valid frame's raw state and return the confirmed state.
    pub(crate) fn push(&mut self, raw: Option<AreaId>) -> Option<AreaId> {
        let m = self.ring.len();
        let code = raw.map_or(self.n_areas, |a| a.0);
        if self.len == m {
            let old = self.ring[self.next] as usize;
            self.counts[old] -= 1;
        } else {
            self.len += 1;
        }
        self.ring[self.next] = code as u16;
        self.next = (self.next + 1) % m;
        self.counts[code] += 1;
        // Strict majority: count > M/2, i.e. 2·count > M. At most one state can hold it.
        if let Some(winner) = self.counts.iter().position(|&c| 2 * c as usize > m) {
            self.state = (winner < self.n_areas).then_some(AreaId(winner));
        }
        self.state
    }
}
