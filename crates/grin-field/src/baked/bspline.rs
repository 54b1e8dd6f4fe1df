//! Cubic B-spline interpolation on a grid: the prefilter that turns node samples into
//! spline coefficients (so the spline passes through the samples: 4th-order values,
//! C2), and the weights with their derivatives (GPU Gems 2 ch. 20; Unser 1999).

/// Pole of the cubic B-spline interpolation filter, sqrt(3) - 2.
const POLE: f64 = -0.267_949_192_431_122_7;

/// Overall gain of the two recursive filters, (1 - z)(1 - 1/z) = 6.
const GAIN: f64 = 6.0;

/// In-place prefilter of one line with mirror boundaries (c[-k] = c[k]): the plain
/// statement of the filter, the reference the tests hold [`prefilter_blocks`] to (bakes
/// use that one).
#[cfg(test)]
pub fn prefilter_line(c: &mut [f64]) {
    let n = c.len();
    if n < 2 {
        return;
    }
    let z = POLE;
    for v in c.iter_mut() {
        *v *= GAIN;
    }
    // Causal initial value for a mirror-symmetric signal, summed to round-off.
    let horizon = ((f64::EPSILON.ln() / z.abs().ln()).ceil() as usize).min(n);
    c[0] = if horizon < n {
        let mut zk = z;
        let mut sum = c[0];
        for v in c.iter().take(horizon).skip(1) {
            sum += zk * v;
            zk *= z;
        }
        sum
    } else {
        // Exact: sum over the full mirrored period 2n - 2.
        let zn = z.powi(n as i32 - 1);
        let iz = 1.0 / z;
        let z2n = zn * zn * iz;
        let mut sum = c[0] + zn * c[n - 1];
        let mut zk = z;
        let mut z2 = z2n;
        for v in c.iter().take(n - 1).skip(1) {
            sum += (zk + z2) * v;
            zk *= z;
            z2 *= iz;
        }
        sum / (1.0 - zn * zn)
    };
    for k in 1..n {
        c[k] += z * c[k - 1];
    }
    c[n - 1] = (z / (z * z - 1.0)) * (c[n - 1] + z * c[n - 2]);
    for k in (0..n - 1).rev() {
        c[k] = z * (c[k + 1] - c[k]);
    }
}

/// In-place prefilter along one axis of many lines at once: `blocks[k][j]` is node `k` of
/// line `j` (every block the same length), each of the `C` channels filtered as
/// `prefilter_line` (the tests' reference) does, in the same order of operations
/// (bit-identical results). Each step of the recursion runs over whole blocks, so lines
/// whose nodes lie a row or a plane apart in memory are filtered with contiguous loops
/// instead of strided gathers.
pub fn prefilter_blocks<const C: usize>(blocks: &mut [&mut [[f64; C]]]) {
    let n = blocks.len();
    if n < 2 {
        return;
    }
    let z = POLE;
    // `a[j] = f(a[j], b[j])` channel by channel, for the blocks of nodes `ka` and `kb`.
    fn combine<const C: usize>(
        blocks: &mut [&mut [[f64; C]]],
        ka: usize,
        kb: usize,
        f: impl Fn(f64, f64) -> f64,
    ) {
        debug_assert_ne!(ka, kb);
        let (lo, hi) = blocks.split_at_mut(ka.max(kb));
        let (a, b): (&mut [[f64; C]], &[[f64; C]]) = if ka < kb {
            (&mut *lo[ka], &*hi[0])
        } else {
            (&mut *hi[0], &*lo[kb])
        };
        for (x, y) in a.iter_mut().zip(b) {
            for c in 0..C {
                x[c] = f(x[c], y[c]);
            }
        }
    }
    for block in blocks.iter_mut() {
        for v in block.iter_mut().flatten() {
            *v *= GAIN;
        }
    }
    let horizon = ((f64::EPSILON.ln() / z.abs().ln()).ceil() as usize).min(n);
    if horizon < n {
        let mut zk = z;
        for k in 1..horizon {
            combine(blocks, 0, k, |s, v| s + zk * v);
            zk *= z;
        }
    } else {
        let zn = z.powi(n as i32 - 1);
        let iz = 1.0 / z;
        let z2n = zn * zn * iz;
        combine(blocks, 0, n - 1, |s, v| s + zn * v);
        let mut zk = z;
        let mut z2 = z2n;
        for k in 1..n - 1 {
            combine(blocks, 0, k, |s, v| s + (zk + z2) * v);
            zk *= z;
            z2 *= iz;
        }
        let d = 1.0 - zn * zn;
        for v in blocks[0].iter_mut().flatten() {
            *v /= d;
        }
    }
    for k in 1..n {
        combine(blocks, k, k - 1, |c, p| c + z * p);
    }
    let g = z / (z * z - 1.0);
    combine(blocks, n - 1, n - 2, |c, p| g * (c + z * p));
    for k in (0..n - 1).rev() {
        combine(blocks, k, k + 1, |c, next| z * (next - c));
    }
}

/// Cubic B-spline weights of the taps at offsets -1, 0, 1, 2 for fraction t in [0, 1).
#[inline]
pub fn weights(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    let t2 = t * t;
    let t3 = t2 * t;
    [
        s * s * s / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    ]
}

/// d/dt of [`weights`].
#[inline]
pub fn weight_derivatives(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    let t2 = t * t;
    [
        -0.5 * s * s,
        1.5 * t2 - 2.0 * t,
        -1.5 * t2 + t + 0.5,
        0.5 * t2,
    ]
}

/// Mirror an index into 0..n (c[-k] = c[k], c[n-1+k] = c[n-1-k]).
#[inline]
pub fn mirror(i: isize, n: usize) -> usize {
    let last = n as isize - 1;
    if last <= 0 {
        return 0;
    }
    let period = 2 * last;
    let mut m = i.rem_euclid(period);
    if m > last {
        m = period - m;
    }
    m as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval(c: &[f64], x: f64) -> f64 {
        let i = x.floor();
        let w = weights(x - i);
        (0..4)
            .map(|k| w[k] * c[mirror(i as isize - 1 + k as isize, c.len())])
            .sum()
    }

    #[test]
    fn prefiltered_spline_interpolates_samples() {
        for n in [2usize, 3, 5, 17, 200] {
            let samples: Vec<f64> = (0..n)
                .map(|i| (i as f64 * 0.7).sin() + 0.1 * i as f64)
                .collect();
            let mut c = samples.clone();
            prefilter_line(&mut c);
            for (i, s) in samples.iter().enumerate() {
                assert!((eval(&c, i as f64) - s).abs() < 1e-12, "n={n} i={i}");
            }
        }
    }

    #[test]
    fn block_prefilter_is_the_line_prefilter_bit_for_bit() {
        // Lengths below and above the causal sum's horizon (exact mirrored sum vs series).
        for n in [2usize, 3, 5, 17, 40, 200] {
            let lines: Vec<Vec<f64>> = (0..3)
                .map(|j| {
                    (0..n)
                        .map(|i| (i as f64 * 0.7 + j as f64).sin() + 0.1 * i as f64)
                        .collect()
                })
                .collect();
            // Node-major storage: data[k * 3 + j] = [line j, -line j] at node k.
            let mut data: Vec<[f64; 2]> = (0..n * 3)
                .map(|i| {
                    let v = lines[i % 3][i / 3];
                    [v, -v]
                })
                .collect();
            let mut blocks: Vec<&mut [[f64; 2]]> = data.chunks_mut(3).collect();
            prefilter_blocks(&mut blocks);
            for (j, line) in lines.iter().enumerate() {
                let mut want = line.clone();
                prefilter_line(&mut want);
                for (k, w) in want.iter().enumerate() {
                    assert_eq!(
                        data[k * 3 + j][0].to_bits(),
                        w.to_bits(),
                        "n={n} line {j} node {k}"
                    );
                    assert_eq!(
                        data[k * 3 + j][1].to_bits(),
                        (-w).to_bits(),
                        "n={n} line {j} node {k}"
                    );
                }
            }
        }
    }

    #[test]
    fn weights_partition_unity_and_derivatives_sum_to_zero() {
        for t in [0.0, 0.25, 0.5, 0.9] {
            let w = weights(t);
            let d = weight_derivatives(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            assert!(d.iter().sum::<f64>().abs() < 1e-15);
            let h = 1e-6;
            let (wp, wm) = (weights(t + h), weights(t - h));
            for k in 0..4 {
                assert!(((wp[k] - wm[k]) / (2.0 * h) - d[k]).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn mirror_indices() {
        assert_eq!(mirror(-1, 5), 1);
        assert_eq!(mirror(-2, 5), 2);
        assert_eq!(mirror(5, 5), 3);
        assert_eq!(mirror(6, 5), 2);
        assert_eq!(mirror(3, 5), 3);
        assert_eq!(mirror(-1, 1), 0);
    }
}
