//! Which Gaussian rows each population owns. The storage layout is fixed — the canonical
//! population first, the transient (time-local) population last — but code asks for a
//! population's [`Rows`], never for a bare count and an "it is the tail" convention.

use std::ops::Range;

/// A half-open range `start..end` of Gaussian rows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Rows {
    pub start: u32,
    pub end: u32,
}

impl Rows {
    pub fn new(start: u32, end: u32) -> Self {
        debug_assert!(start <= end, "Rows {start}..{end}");
        Rows { start, end }
    }

    pub fn len(self) -> u32 {
        self.end - self.start
    }

    pub fn is_empty(self) -> bool {
        self.end == self.start
    }

    pub fn contains(self, row: u32) -> bool {
        (self.start..self.end).contains(&row)
    }

    /// As an index range (host vectors).
    pub fn range(self) -> Range<usize> {
        self.start as usize..self.end as usize
    }
}

/// The live rows split into populations: canonical rows `0..k`, transient rows `k..n`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Populations {
    /// What the deformation moves (static and deforming Gaussians alike).
    pub canonical: Rows,
    /// Time-local Gaussians (`kernels::temporal`), after the canonical ones.
    pub transient: Rows,
}

impl Populations {
    /// `n` live rows, the last `transients` of them (at most `n`) transient.
    pub fn split(n: u32, transients: u32) -> Self {
        let k = n - transients.min(n);
        Populations {
            canonical: Rows::new(0, k),
            transient: Rows::new(k, n),
        }
    }

    /// Whether the rows carry the temporal sections (time centre and width, velocity): only
    /// transients have them, so storage and files hold them only when some row is one.
    pub fn temporal(self) -> bool {
        !self.transient.is_empty()
    }

    /// Live rows of every population.
    pub fn len(self) -> u32 {
        self.transient.end
    }

    pub fn is_empty(self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_puts_transients_last_and_clamps() {
        let p = Populations::split(10, 3);
        assert_eq!(p.canonical, Rows::new(0, 7));
        assert_eq!(p.transient, Rows::new(7, 10));
        assert_eq!(p.len(), 10);
        assert!(p.transient.contains(7) && !p.transient.contains(6));
        let all = Populations::split(4, 9);
        assert!(all.canonical.is_empty());
        assert_eq!(all.transient.range(), 0..4);
        assert!(Populations::split(5, 0).transient.is_empty());
    }
}
