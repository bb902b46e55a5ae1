#!/usr/bin/env python3
"""Write scipy's answers on seeded data into src/stats/scipy_reference.json (issue 5).

The Rust test `stats::reference_tests` reads that fixture; CI runs the test, not this script.
Regenerate after changing a case (the output is deterministic for given scipy/numpy versions):

    python3 -m venv /tmp/stats-venv && /tmp/stats-venv/bin/pip install scipy numpy statsmodels
    /tmp/stats-venv/bin/python scripts/stats_reference.py

Cases:
* wilcoxon: paired samples, n = 5..40, continuous (no ties, no zeros), rounded (ties), and with
  zero differences; every zero_method (wilcox, pratt, zsplit) x correction (False, True) with
  scipy's method="auto" (exact / sign-flip permutation / normal, as scipy chooses), plus
  method="asymptotic" on the untied data too. The rank-biserial correlation is computed here
  with numpy from scipy's rankdata (scipy has no function for it).
* friedman: k = 3 (and some k = 4) conditions x n = 5..40 participants, continuous and tied
  (integer ratings); friedmanchisquare; Kendall's W = chi2 / (n (k - 1)).
* holm: families of 1..12 p-values (with repeats and values near 1); statsmodels
  multipletests(method="holm") (scipy has no Holm), cross-checked against a direct numpy version.
* spearman: n = 5..40 with and without ties, spearmanr (t-approximation); n = 5..8 exact
  permutation p by permutation_test(permutation_type="pairings", n_resamples=inf).

Every float is stored as a JSON number and, for bit-exact comparisons, as its IEEE-754 bit
pattern (`*_bits`, an integer). Data values are rounded to 4 decimals so their JSON text is short
and parses exactly.
"""

import json
import struct
import sys
from pathlib import Path

import numpy as np
import scipy
from scipy import stats

try:
    import statsmodels
    from statsmodels.stats.multitest import multipletests
except ImportError:  # pragma: no cover - the fixture records which reference was used
    statsmodels = None

OUT = Path(__file__).resolve().parent.parent / "src" / "stats" / "scipy_reference.json"


def bits(x: float) -> int:
    return struct.unpack("<Q", struct.pack("<d", float(x)))[0]


def num(x: float) -> dict:
    return {"value": float(x), "bits": bits(x)}


def data(a) -> list:
    return [float(v) for v in np.round(np.asarray(a, dtype=float), 4)]


def wilcoxon_auto_method(d, zero_method):
    """scipy 1.17's method="auto" rule (scipy/stats/_wilcoxon.py), for the record."""
    n = len(d)
    n_zero = int(np.count_nonzero(d == 0))
    ranked = d[d != 0] if zero_method == "wilcox" else d
    _, counts = np.unique(np.abs(ranked), return_counts=True)
    has_ties = bool(np.any(counts > 1))
    if n > 50:
        return "asymptotic"
    if not (has_ties or n_zero > 0):
        return "exact"
    return "permutation" if n <= 13 else "asymptotic"


def rank_biserial(d, zero_method):
    d = np.asarray(d)
    ranked = d[d != 0] if zero_method == "wilcox" else d
    r = stats.rankdata(np.abs(ranked))
    plus = r[ranked > 0].sum()
    minus = r[ranked < 0].sum()
    if zero_method == "zsplit":
        half = r[ranked == 0].sum() / 2
        plus, minus = plus + half, minus + half
    return (plus - minus) / (plus + minus)


def wilcoxon_cases(rng):
    cases = []
    for n in [5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 18, 20, 25, 30, 40]:
        for kind in ["continuous", "ties", "zeros"]:
            x = rng.normal(10.0, 2.0, n)
            y = x + rng.normal(0.6, 1.5, n)
            if kind == "ties":
                x, y = np.round(x), np.round(y * 2) / 2
                # Make sure |d| has ties but keep some non-zero differences.
            elif kind == "zeros":
                x, y = np.round(x, 1), np.round(y, 1)
                k = max(1, n // 5)
                y[:k] = x[:k]
            x, y = np.array(data(x)), np.array(data(y))
            d = x - y
            if np.all(d == 0):
                continue
            for zero_method in ["wilcox", "pratt", "zsplit"]:
                if kind == "continuous" and zero_method != "wilcox":
                    continue  # no zeros: the three methods coincide
                methods = ["auto"] + (["asymptotic"] if kind == "continuous" else [])
                for method in methods:
                    for correction in [False, True]:
                        if method == "auto" and correction and wilcoxon_auto_method(d, zero_method) != "asymptotic":
                            continue  # the correction only affects the normal approximation
                        res = stats.wilcoxon(x, y, zero_method=zero_method, correction=correction, method=method)
                        used = wilcoxon_auto_method(d, zero_method) if method == "auto" else method
                        cases.append({
                            "name": f"wilcoxon n={n} {kind} {zero_method} {method} correction={correction}",
                            "x": list(x), "y": list(y),
                            "zero_method": zero_method, "correction": correction, "method": method,
                            "method_used": used,
                            "statistic": num(res.statistic), "pvalue": num(res.pvalue),
                            "rank_biserial": num(rank_biserial(d, zero_method)),
                        })
    return cases


def friedman_cases(rng):
    cases = []
    for n in [5, 6, 8, 10, 12, 15, 20, 25, 30, 40]:
        for k in [3, 4] if n in (6, 10, 20) else [3]:
            for kind in ["continuous", "ties"]:
                base = rng.normal(0.0, 1.0, (n, 1))
                effect = np.linspace(0.0, 0.8, k)
                m = base + effect + rng.normal(0.0, 1.0, (n, k))
                if kind == "ties":
                    m = np.clip(np.round(m * 1.5 + 3), 1, 5)  # 1-5 ratings: many ties
                m = np.array([data(row) for row in m])
                if np.all(m == m[:, :1]):
                    continue
                res = stats.friedmanchisquare(*[m[:, j] for j in range(k)])
                cases.append({
                    "name": f"friedman n={n} k={k} {kind}",
                    "blocks": [list(row) for row in m],
                    "statistic": num(res.statistic), "pvalue": num(res.pvalue),
                    "kendall_w": num(res.statistic / (n * (k - 1))),
                })
    return cases


def holm_numpy(p):
    p = np.asarray(p, dtype=float)
    m = len(p)
    order = np.argsort(p, kind="stable")
    adj = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adj = np.maximum.accumulate(adj)
    out = np.empty(m)
    out[order] = adj
    return out


def holm_cases(rng):
    cases = []
    for m in [1, 2, 3, 4, 5, 6, 8, 10, 12]:
        for variant in range(2):
            p = rng.uniform(0.0, 0.2 if variant == 0 else 1.0, m) ** 2
            if m >= 3:
                p[1] = p[0]  # a repeated p-value
            p = np.array(data(np.maximum(p, 1e-4)))
            ref = holm_numpy(p)
            if statsmodels is not None:
                sm = multipletests(p, method="holm")[1]
                assert np.allclose(sm, ref, rtol=0, atol=1e-15), (p, sm, ref)
                ref = sm
            cases.append({"name": f"holm m={m} #{variant}", "p": list(p), "adjusted": [num(v) for v in ref]})
    return cases


def spearman_cases(rng):
    cases = []
    for n in [5, 6, 7, 8, 10, 12, 15, 20, 30, 40]:
        for kind in ["continuous", "ties"]:
            x = rng.normal(0.0, 1.0, n)
            y = 0.5 * x + rng.normal(0.0, 1.0, n)
            if kind == "ties":
                x, y = np.round(x * 1.5), np.round(y * 1.5)
            x, y = np.array(data(x)), np.array(data(y))
            if np.all(x == x[0]) or np.all(y == y[0]):
                continue
            res = stats.spearmanr(x, y)
            case = {
                "name": f"spearman n={n} {kind}", "x": list(x), "y": list(y),
                "rho": num(res.statistic), "pvalue_t": num(res.pvalue),
            }
            if n <= 8:
                ry = stats.rankdata(y)

                def statistic(xp, axis=-1):
                    rx = stats.rankdata(xp, axis=axis)
                    rxc = rx - rx.mean(axis=axis, keepdims=True)
                    ryc = ry - ry.mean()
                    return (rxc * ryc).sum(axis=axis) / np.sqrt((rxc**2).sum(axis=axis) * (ryc**2).sum())

                perm = stats.permutation_test((x,), statistic, permutation_type="pairings",
                                              n_resamples=np.inf, vectorized=True, alternative="two-sided")
                case["pvalue_exact"] = num(perm.pvalue)
            cases.append(case)
    return cases


def main():
    rng = np.random.default_rng(20260505)
    fixture = {
        "generator": "scripts/stats_reference.py",
        "versions": {
            "python": sys.version.split()[0],
            "scipy": scipy.__version__,
            "numpy": np.__version__,
            "statsmodels": None if statsmodels is None else statsmodels.__version__,
        },
        "seed": 20260505,
        "wilcoxon": wilcoxon_cases(rng),
        "friedman": friedman_cases(rng),
        "holm": holm_cases(rng),
        "spearman": spearman_cases(rng),
    }
    OUT.write_text(json.dumps(fixture, indent=1) + "\n")
    counts = {k: len(v) for k, v in fixture.items() if isinstance(v, list)}
    print(f"wrote {OUT}: {counts}")


if __name__ == "__main__":
    main()
