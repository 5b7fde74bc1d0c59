#!/usr/bin/env python3
"""Fits the polynomial of src/raster/fast_exp.hpp: p(r) = 1 + r*q(r) ~ e^r on |r| <= ln2/2.

q has degree 4 and minimizes the largest relative error max |p(r)/e^r - 1|. Writing
p(r)/e^r - 1 = w(r) * (q(r) - f(r)) with f(r) = (e^r - 1)/r and w(r) = |r| e^-r (up to sign)
makes it a weighted minimax problem for q, solved by the Remez exchange: solve for q and the
levelled error E on degree + 2 reference points, move the points to the error's extrema,
repeat. p(0) = 1 is built in, so exp(0) = 1 exactly.

Plain Python (no numpy), double precision, well below float32's resolution. Run it and copy
the coefficients (highest power first) into fast_exp.hpp; tests/test_stage_math.cpp checks
the result against std::exp.
"""
import math

DEGREE_Q = 4
LO, HI = -math.log(2) / 2, math.log(2) / 2
GRID = 20001


def f(r):
    return math.expm1(r) / r if r != 0 else 1.0


def w(r):
    return abs(r) * math.exp(-r)


def solve(a, y):
    """Gauss-Jordan elimination with partial pivoting."""
    n = len(y)
    m = [row[:] + [y[i]] for i, row in enumerate(a)]
    for c in range(n):
        p = max(range(c, n), key=lambda i: abs(m[i][c]))
        m[c], m[p] = m[p], m[c]
        for i in range(n):
            if i != c:
                t = m[i][c] / m[c][c]
                m[i] = [u - t * v for u, v in zip(m[i], m[c])]
    return [m[i][n] / m[i][i] for i in range(n)]


def weighted_error(q, r):
    return w(r) * (sum(c * r**k for k, c in enumerate(q)) - f(r))


def main():
    n = DEGREE_Q + 2
    # Chebyshev extrema as the first reference.
    ref = [(LO + HI) / 2 - (HI - LO) / 2 * math.cos(math.pi * k / (n - 1)) for k in range(n)]
    xs = [LO + (HI - LO) * i / (GRID - 1) for i in range(GRID)]
    for _ in range(30):
        rows = [[x**k for k in range(DEGREE_Q + 1)] + [(-1) ** i / w(x)] for i, x in enumerate(ref)]
        sol = solve(rows, [f(x) for x in ref])
        q, levelled = sol[:-1], sol[-1]
        es = [weighted_error(q, x) for x in xs]
        # One extremum per run of equal sign.
        runs, start = [], 0
        for i in range(1, GRID):
            if (es[i] > 0) != (es[i - 1] > 0):
                runs.append((start, i))
                start = i
        runs.append((start, GRID))
        ext = [max(range(s, e), key=lambda i: abs(es[i])) for s, e in runs]
        if len(ext) < n:
            break
        best = max((ext[j:j + n] for j in range(len(ext) - n + 1)), key=lambda idx: min(abs(es[i]) for i in idx))
        ref = [xs[i] for i in best]
    worst = max(abs(e) for e in es)
    print(f"levelled error {abs(levelled):.3e}, largest on the grid {worst:.3e}")
    print("p(r) = 1 + r*(c1 + c2 r + ...), highest power first:")
    for k in reversed(range(DEGREE_Q + 1)):
        print(f"  c{k + 1} = {q[k]:.9e}f")


if __name__ == "__main__":
    main()
