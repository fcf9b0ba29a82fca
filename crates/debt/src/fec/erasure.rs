//! Lost data shards of one block rebuilt in closed form: the code `reed-solomon-erasure`'s
//! `galois_8::ReedSolomon::new(d, p)` builds, decoded without inverting a `d x d` matrix.
//!
//! The crate's code matrix is the Vandermonde matrix of the points `0, 1, .., d + p - 1` times
//! the inverse of its top `d x d` square. So parity shard `r` is, byte by byte, the value at
//! `x = d + r` of the polynomial of degree below `d` that takes data shard `i`'s byte at point
//! `i`: its coefficient for data shard `i` is the Lagrange basis polynomial
//! `L_i(x) = N(x) / ((x + i) D_i)`, with `N(x) = prod_{j<d} (x + j)` and
//! `D_i = prod_{j<d, j!=i} (i + j)` (`+` is xor in GF(2^8)).
//!
//! With the data shards at the points `y_c` lost (`e` of them), the first `e` parity shards that
//! arrived (points `x_r`), as the crate's decoder takes them, give `e` equations
//! `sum_c u_c / (x_r + y_c) = t_r`, where `u_c` is lost shard `c` over `D_{y_c}` and `t_r` is
//! parity shard `r` less the arrived data shards' part, over `N(x_r)`. That is a Cauchy
//! system, whose inverse is known: with `W(z) = prod_c (z + y_c)` and `V(z) = prod_r (z + x_r)`,
//! `u_c = V(y_c) / W'(y_c) * sum_r W(x_r) / (V'(x_r) (y_c + x_r)) * t_r`. A block costs
//! `e` passes over its `d` shards and `O(e^2 + e d)` field operations, where the crate inverts
//! a `d x d` matrix (`O(d^3)`, 250 shards a block) for every loss pattern.
//!
//! The system has one solution, so the bytes rebuilt are the crate's on any input, consistent
//! with its parity or not (the tests compare the two on random shards and losses).

use reed_solomon_erasure::galois_8::{div, mul, mul_slice_xor};

/// Most shards (data and parity) a code over GF(2^8) has: one point each.
const MAX_SHARDS: usize = 256;

/// `1 / a` in GF(2^8); `a` is never 0 here (a difference of two distinct points).
fn inverse(a: u8) -> u8 {
    div(1, a)
}

/// The product of `x + p` over the points `p` (`+` is xor).
fn product(x: u8, points: impl IntoIterator<Item = u8>) -> u8 {
    points.into_iter().fold(1, |acc, p| mul(acc, x ^ p))
}

/// A point's field element: shard index `i` of a code of at most [`MAX_SHARDS`] shards.
fn point(i: usize) -> u8 {
    i as u8
}

/// What the codes of a search share, by data shard count `d`: `1 / D_i` for `i < d`, built
/// once each (`O(d^2)`), so that a block costs only its own loss pattern.
#[derive(Debug, Default)]
pub(super) struct Codes {
    /// Indexed by `d`; empty until a block of `d` data shards needs it.
    inverse_denominators: Vec<Vec<u8>>,
}

impl Codes {
    /// `1 / D_i` for the `d` data points.
    fn inverse_denominators(&mut self, d: usize) -> &[u8] {
        if self.inverse_denominators.len() <= d {
            self.inverse_denominators.resize(d + 1, Vec::new());
        }
        let slot = &mut self.inverse_denominators[d];
        if slot.is_empty() {
            *slot = (0..d)
                .map(|i| inverse(product(point(i), (0..d).filter(|&j| j != i).map(point))))
                .collect();
        }
        slot
    }

    /// Rebuilds the lost data shards of a block of `shards.len()` shards, `data` of them data
    /// (first) and the rest parity; `None` is a lost shard, a shard shorter than `len` bytes is
    /// zero-padded. Returns each lost data shard's index and its `len` bytes; nothing when no data
    /// shard is lost, when more are lost than parity shards arrived, or for a shape the crate
    /// refuses (no data or no parity shard, more than 256 shards).
    pub(super) fn rebuild(
        &mut self,
        shards: &[Option<&[u8]>],
        data: usize,
        len: usize,
    ) -> Vec<(usize, Vec<u8>)> {
        if data == 0 || data >= shards.len() || shards.len() > MAX_SHARDS {
            return Vec::new();
        }
        let lost: Vec<usize> = (0..data).filter(|&i| shards[i].is_none()).collect();
        let rows: Vec<usize> = (data..shards.len())
            .filter(|&j| shards[j].is_some())
            .take(lost.len())
            .collect();
        if lost.is_empty() || rows.len() < lost.len() {
            return Vec::new();
        }
        let inverse_denominators = self.inverse_denominators(data);
        let ys = || lost.iter().map(|&i| point(i));
        let xs = || rows.iter().map(|&j| point(j));
        // t_r, scaled by W(x_r) / V'(x_r).
        let t: Vec<Vec<u8>> = rows
            .iter()
            .map(|&j| {
                let x = point(j);
                let scale = div(
                    product(x, ys()),
                    product(x, xs().filter(|&other| other != x)),
                );
                let mut acc = vec![0u8; len];
                add_scaled(
                    &mut acc,
                    div(scale, product(x, (0..data).map(point))),
                    shards[j],
                );
                for (i, shard) in shards[..data].iter().enumerate() {
                    if shard.is_some() {
                        let weight = mul(inverse_denominators[i], inverse(x ^ point(i)));
                        add_scaled(&mut acc, mul(scale, weight), *shard);
                    }
                }
                acc
            })
            .collect();
        lost.iter()
            .map(|&i| {
                let y = point(i);
                let denominator = mul(
                    inverse_denominators[i],
                    product(y, ys().filter(|&other| other != y)),
                );
                let scale = div(product(y, xs()), denominator);
                let mut shard = vec![0u8; len];
                for (&j, t_r) in rows.iter().zip(&t) {
                    add_scaled(&mut shard, div(scale, y ^ point(j)), Some(t_r));
                }
                (i, shard)
            })
            .collect()
    }
}

/// `acc += c * shard` byte by byte (a shorter shard is zero-padded, a longer one cut).
fn add_scaled(acc: &mut [u8], c: u8, shard: Option<&[u8]>) {
    let shard = shard.unwrap_or_default();
    let n = shard.len().min(acc.len());
    mul_slice_xor(c, &shard[..n], &mut acc[..n]);
}

#[cfg(test)]
mod tests {
    use super::super::tests::rng;
    use super::*;
    use reed_solomon_erasure::galois_8::ReedSolomon;

    /// The crate's own decoder on the same shards.
    fn crate_rebuild(shards: &[Option<Vec<u8>>], data: usize) -> Option<Vec<Option<Vec<u8>>>> {
        let rs = ReedSolomon::new(data, shards.len() - data).ok()?;
        let mut out = shards.to_vec();
        rs.reconstruct_data(&mut out).ok()?;
        Some(out)
    }

    #[test]
    fn the_parity_coefficients_are_the_lagrange_basis_of_the_crate_s_code() {
        // Data shard i a unit vector: parity shard r is then its column of coefficients.
        for (d, p) in [(1, 1), (3, 2), (10, 4), (50, 50), (200, 52)] {
            let rs = ReedSolomon::new(d, p).unwrap();
            let mut shards: Vec<Vec<u8>> = (0..d + p)
                .map(|s| (0..d).map(|i| u8::from(s == i)).collect())
                .collect();
            rs.encode(&mut shards).unwrap();
            let mut codes = Codes::default();
            let inverse_denominators = codes.inverse_denominators(d).to_vec();
            for r in 0..p {
                let x = point(d + r);
                for i in 0..d {
                    let lagrange = div(
                        product(x, (0..d).map(point)),
                        mul(x ^ point(i), inverse(inverse_denominators[i])),
                    );
                    assert_eq!(shards[d + r][i], lagrange, "d {d} p {p} r {r} i {i}");
                }
            }
        }
    }

    #[test]
    fn rebuilt_shards_are_the_crate_s_on_any_bytes_and_losses() {
        let mut next = rng(48);
        for round in 0..200 {
            let d = 1 + (next() % 40) as usize;
            let p = 1 + (next() % 30) as usize;
            // One block of the size streams have (the crate is slow unoptimised).
            let (d, p) = if round == 0 { (125, 125) } else { (d, p) };
            let len = 1 + (next() % 20) as usize;
            // Random bytes: consistent with a code for half the rounds, garbage for the rest.
            let mut shards: Vec<Vec<u8>> = (0..d + p)
                .map(|_| (0..len).map(|_| next() as u8).collect())
                .collect();
            if round % 2 == 0 {
                ReedSolomon::new(d, p).unwrap().encode(&mut shards).unwrap();
            }
            let lose = (next() % (p as u64 + 3)) as usize;
            let mut received: Vec<Option<Vec<u8>>> = shards.into_iter().map(Some).collect();
            for _ in 0..lose {
                let at = (next() % (d + p) as u64) as usize;
                received[at] = None;
            }
            let borrowed: Vec<Option<&[u8]>> = received.iter().map(|s| s.as_deref()).collect();
            let ours = Codes::default().rebuild(&borrowed, d, len);
            let lost_data = (0..d).filter(|&i| received[i].is_none()).count();
            match crate_rebuild(&received, d) {
                Some(theirs) if lost_data > 0 => {
                    assert_eq!(ours.len(), lost_data, "round {round}");
                    for (i, bytes) in ours {
                        assert_eq!(theirs[i].as_deref(), Some(&bytes[..]), "round {round}");
                    }
                }
                _ => assert!(ours.is_empty(), "round {round}"),
            }
        }
    }

    #[test]
    fn short_shards_are_zero_padded_and_bad_shapes_rebuild_nothing() {
        let rs = ReedSolomon::new(3, 2).unwrap();
        let mut shards = vec![
            vec![1, 2, 3, 4],
            vec![5, 6, 7, 8],
            vec![9, 0, 0, 0],
            vec![0; 4],
            vec![0; 4],
        ];
        rs.encode(&mut shards).unwrap();
        let short = [9u8];
        let received = [
            None,
            Some(&shards[1][..]),
            Some(&short[..]),
            Some(&shards[3][..]),
            None,
        ];
        assert_eq!(
            Codes::default().rebuild(&received, 3, 4),
            vec![(0, shards[0].clone())]
        );
        let mut codes = Codes::default();
        assert!(codes.rebuild(&received, 0, 4).is_empty());
        assert!(codes.rebuild(&received, 5, 4).is_empty());
        assert!(codes.rebuild(&vec![None; 257], 200, 4).is_empty());
    }
}
