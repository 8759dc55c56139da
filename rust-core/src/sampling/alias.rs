//! Vose's alias method: a discrete law drawn with one uniform and two
//! table reads, no search, so that a program (one gather per read) and the
//! native path draw the same law.

use crate::program::Real;

/// A discrete law over `len()` entries as an alias table.
#[derive(Clone, Debug)]
pub struct AliasTable {
    /// Per entry: the probability of keeping it (f32), then the entry it
    /// passes the rest to (an index, exact in f32 below 2^24): the layout
    /// a program gathers from.
    pub interleaved: Vec<f32>,
    /// Each entry's probability under the table as stored (the f32 keep
    /// probabilities), so that a density taken from it is exactly the law
    /// drawn.
    pub probability: Vec<f64>,
}

impl AliasTable {
    /// The table of the law proportional to `mass` (non-negative, not all
    /// zero; all zero gives the uniform law).
    pub fn new(mass: &[f64]) -> AliasTable {
        let entries = mass.len();
        let total: f64 = mass.iter().sum();
        let mut scaled: Vec<f64> = if total > 0.0 {
            mass.iter().map(|m| m / total * entries as f64).collect()
        } else {
            vec![1.0; entries]
        };
        let mut keep = vec![1.0; entries];
        let mut alias: Vec<usize> = (0..entries).collect();
        let (mut small, mut large): (Vec<usize>, Vec<usize>) =
            (0..entries).partition(|&i| scaled[i] < 1.0);
        while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
            keep[s] = scaled[s];
            alias[s] = l;
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        let interleaved: Vec<f32> = (0..entries)
            .flat_map(|e| [keep[e] as f32, alias[e] as f32])
            .collect();
        let mut probability = vec![0.0; entries];
        for e in 0..entries {
            let k = interleaved[2 * e] as f64;
            probability[e] += k / entries as f64;
            probability[alias[e]] += (1.0 - k) / entries as f64;
        }
        AliasTable {
            interleaved,
            probability,
        }
    }

    pub fn len(&self) -> usize {
        self.probability.len()
    }

    pub fn is_empty(&self) -> bool {
        self.probability.is_empty()
    }

    /// The entry drawn by the uniform `r` in [0, 1) (`draw_alias`).
    pub fn draw(&self, r: f64) -> usize {
        draw_alias(r, self.len(), |at: f64| {
            self.interleaved[at as usize] as f64
        }) as usize
    }

    pub fn memory_bytes(&self) -> usize {
        self.interleaved.len() * 4 + self.probability.len() * 8
    }
}

/// The entry (as a number) that the uniform `r` in [0, 1) draws from an
/// alias table of `entries` entries laid out as `AliasTable::interleaved`,
/// read through `fetch` (an index natively, a gather in a program): the
/// entry from r times the count, the keep test from its fraction.
pub fn draw_alias<R: Real>(r: R, entries: usize, fetch: impl Fn(R) -> R) -> R {
    let x = r * entries as f64;
    let i = x.floor().min((entries - 1) as f64);
    let keep = fetch(i * 2.0);
    R::select((x - i - keep).lt(0.0), i, fetch(i * 2.0 + 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_follow_the_stored_law() {
        let mass = [0.0, 3.0, 1.0, 0.5, 0.0, 2.5];
        let table = AliasTable::new(&mass);
        let total: f64 = mass.iter().sum();
        for (p, m) in table.probability.iter().zip(mass) {
            assert!((p - m / total).abs() < 1e-7, "{p} vs {}", m / total);
        }
        let n = 600_000;
        let mut counts = [0usize; 6];
        for i in 0..n {
            counts[table.draw((i as f64 + 0.5) / n as f64)] += 1;
        }
        for (c, p) in counts.iter().zip(&table.probability) {
            assert!((*c as f64 / n as f64 - p).abs() < 1e-4, "{c} vs {p}");
        }
        assert_eq!(counts[0] + counts[4], 0);
    }
}
