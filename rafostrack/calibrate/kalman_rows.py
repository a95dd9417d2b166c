"""Whitened residual rows with their sparse Jacobian (`Rows`), and their normal-equation
terms (`Normal`): the batch Kalman smoother's linear algebra (`calibrate.kalman`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import sparse


@dataclass(frozen=True)
class Block:
    """Rows with the same number e of Jacobian entries: whitened residuals (m,), and each
    row's entries as columns and values (m, e)."""

    residual: NDArray[np.float64]
    cols: NDArray[np.intp]
    vals: NDArray[np.float64]


@dataclass
class Rows:
    """Whitened residual rows r(u) with their sparse Jacobian, and log|W| of the whitening."""

    blocks: list[Block] = dataclasses.field(default_factory=list)
    log_whitening: float = 0.0
    n: int = 0

    def add(self, residual: NDArray, entries: list[tuple[NDArray, NDArray]], log_whitening: float) -> None:
        """Rows with whitened residuals `residual` (m,) and Jacobian entries, each a pair
        (columns (m,), values (m,)): one nonzero per row per pair."""
        m = len(residual)
        cols, vals = np.empty((m, len(entries)), dtype=np.intp), np.empty((m, len(entries)))
        for a, (col, val) in enumerate(entries):  # each broadcast to the rows
            cols[:, a], vals[:, a] = col, val
        self.blocks.append(Block(np.asarray(residual, dtype=float), cols, vals))
        self.log_whitening += log_whitening
        self.n += m

    def system(self, n_unknowns: int) -> tuple[sparse.csr_matrix, NDArray[np.float64]]:
        starts = np.cumsum([0] + [len(b.residual) for b in self.blocks])[:-1]
        rows = [
            np.repeat(start + np.arange(len(b.residual)), b.cols.shape[1])
            for start, b in zip(starts, self.blocks, strict=True)
        ]
        jac = sparse.csr_matrix(
            (
                np.concatenate([b.vals.ravel() for b in self.blocks]),
                (np.concatenate(rows), np.concatenate([b.cols.ravel() for b in self.blocks])),
            ),
            shape=(self.n, n_unknowns),
        )
        return jac, np.concatenate([b.residual for b in self.blocks])

    def stacked(self) -> Block:
        """All rows as one block, each row's entries padded to the widest row's with column
        -1 and value 0 (`BorderedBanded.inverse_times_rows`)."""
        width = max(b.cols.shape[1] for b in self.blocks)
        cols = np.full((self.n, width), -1, dtype=np.intp)
        vals = np.zeros((self.n, width))
        start = 0
        for b in self.blocks:
            m, e = b.cols.shape
            cols[start : start + m, :e] = b.cols
            vals[start : start + m, :e] = b.vals
            start += m
        return Block(np.concatenate([b.residual for b in self.blocks]), cols, vals)


@dataclass(frozen=True)
class Normal:
    """A group of rows reduced to its normal-equation terms: J'J, J'r, r'r and log|W|."""

    jtj: sparse.csr_matrix
    jtr: NDArray[np.float64]
    rtr: float
    log_whitening: float

    @classmethod
    def of(cls, rows: Rows, n_unknowns: int) -> Normal:
        return cls.of_system(*rows.system(n_unknowns), rows.log_whitening)

    @classmethod
    def of_system(cls, jac: sparse.csr_matrix, r: NDArray, log_whitening: float) -> Normal:
        return cls((jac.T @ jac).tocsr(), jac.T @ r, float(r @ r), log_whitening)
