"""A small discrete Bayesian network with exact inference (paper section II-A, Fig. 1).

The paper turns context variables (surface type, intelligence about it, vehicle type; for a
float: the grid depth, its uncertainty class, the land mask, the float's depth) into a
corrective factor CF = P(m = true | context) by exact inference in a discrete Bayesian
network. A network here is a list of nodes, each with its states, its parents and its
conditional probability table P(node | parents), in topological order. The joint is
    P(v_1, ..., v_n) = prod_k P(v_k | parents(v_k)),
and a query sums it exactly over every variable that is neither queried nor given:
    P(q | e) = sum_h P(q, e, h) / sum_{q, h} P(q, e, h).

Why our own ~150 lines and not pgmpy: the networks here have a handful of nodes, and the
float's has one hidden variable of a few hundred states; what the context grid needs is the
whole table P(q | e) for every combination of evidence states at once (then each cell looks
its CF up), which one `numpy.einsum` contraction over the CPTs gives exactly (its
contraction order is variable elimination). pgmpy answers one evidence set per call and
would bring torch, networkx, scikit-learn and more for that. The tests check the result
against brute-force enumeration of the joint and against the textbook burglary network.
"""

from __future__ import annotations

import string
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

_LETTERS = string.ascii_letters  # einsum subscripts: at most 52 variables
_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Node:
    """One discrete variable: its states, its parents and P(node | parents), an array of
    shape (*parent sizes, len(states)) whose last axis sums to 1."""

    name: str
    states: tuple[str, ...]
    parents: tuple[str, ...]
    cpt: NDArray[np.float64]


class DiscreteBayesNet:
    """A discrete Bayesian network with exact queries (module docstring)."""

    def __init__(self, nodes: Sequence[Node]):
        """Check the nodes: unique names, parents defined earlier, CPT shapes, rows summing to 1."""
        self.nodes: dict[str, Node] = {}
        for node in nodes:
            if node.name in self.nodes:
                raise ValueError(f"node {node.name!r} defined twice")
            missing = [p for p in node.parents if p not in self.nodes]
            if missing:
                raise ValueError(f"node {node.name!r}: parent(s) {missing} must be defined before it")
            cpt = np.asarray(node.cpt, dtype=float)
            shape = (*(len(self.nodes[p].states) for p in node.parents), len(node.states))
            if cpt.shape != shape:
                raise ValueError(f"node {node.name!r}: CPT shape {cpt.shape}, expected {shape}")
            if np.any(cpt < 0) or not np.allclose(cpt.sum(axis=-1), 1.0, atol=1e-9):
                raise ValueError(f"node {node.name!r}: CPT rows must be probabilities summing to 1")
            self.nodes[node.name] = Node(node.name, tuple(node.states), tuple(node.parents), cpt)
        if len(self.nodes) > len(_LETTERS):
            raise ValueError(f"at most {len(_LETTERS)} variables")

    def states(self, name: str) -> tuple[str, ...]:
        return self.nodes[name].states

    def state_index(self, name: str, state: str | int) -> int:
        """The index of `state` (a name or an index) of variable `name`."""
        states = self.nodes[name].states
        if isinstance(state, str):
            if state not in states:
                raise ValueError(f"{name!r} has no state {state!r}; states: {', '.join(states)}")
            return states.index(state)
        if not 0 <= int(state) < len(states):
            raise ValueError(f"{name!r}: state index {state} out of range 0..{len(states) - 1}")
        return int(state)

    def joint_table(self, keep: Sequence[str]) -> NDArray[np.float64]:
        """P(keep) as an array over the kept variables' states (in the order of `keep`):
        the joint summed exactly over every other variable."""
        unknown = [k for k in keep if k not in self.nodes]
        if unknown:
            raise ValueError(f"unknown variable(s) {unknown}; known: {', '.join(self.nodes)}")
        if len(set(keep)) != len(keep):
            raise ValueError(f"variables repeated in {list(keep)}")
        letter = {name: _LETTERS[i] for i, name in enumerate(self.nodes)}
        tables = [node.cpt for node in self.nodes.values()]
        subscripts = ["".join(letter[v] for v in (*node.parents, node.name)) for node in self.nodes.values()]
        spec = ",".join(subscripts) + "->" + "".join(letter[k] for k in keep)
        out: NDArray[np.float64] = np.einsum(spec, *tables, optimize="greedy")
        return out

    def posterior_table(self, query: str, given: Sequence[str]) -> NDArray[np.float64]:
        """P(query | given) for every combination of the given variables' states: an array
        of shape (*given sizes, query size); NaN where the evidence has probability 0."""
        joint = self.joint_table([*given, query])
        total = joint.sum(axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, joint / np.where(total > 0, total, 1.0), np.nan)

    def posterior(self, query: str, evidence: Mapping[str, str | int]) -> NDArray[np.float64]:
        """P(query | evidence) over the query's states, for one evidence set."""
        names = list(evidence)
        table = self.posterior_table(query, names)
        index = tuple(self.state_index(n, evidence[n]) for n in names)
        out = table[index]
        if np.isnan(out).any():
            raise ValueError(f"evidence {dict(evidence)} has probability 0 under the network")
        return out


def binary_cpt(p_true: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """A CPT of a binary node (states false, true) from P(true | parents)."""
    p = np.asarray(p_true, dtype=float)
    if np.any((p < -_TOLERANCE) | (p > 1 + _TOLERANCE)):
        raise ValueError("P(true) must be in [0, 1]")
    p = np.clip(p, 0.0, 1.0)
    return np.stack([1.0 - p, p], axis=-1)
