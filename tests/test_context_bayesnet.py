"""The discrete Bayesian network: exact queries against brute-force enumeration and a
textbook network."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from rafostrack.context.bayesnet import DiscreteBayesNet, Node, binary_cpt


def _random_cpt(rng, shape):
    t = rng.random(shape) + 0.05
    return t / t.sum(axis=-1, keepdims=True)


def _random_net(rng) -> DiscreteBayesNet:
    return DiscreteBayesNet(
        [
            Node("a", ("0", "1", "2"), (), _random_cpt(rng, (3,))),
            Node("b", ("0", "1"), ("a",), _random_cpt(rng, (3, 2))),
            Node("c", ("0", "1", "2", "3"), ("a",), _random_cpt(rng, (3, 4))),
            Node("d", ("0", "1"), ("b", "c"), _random_cpt(rng, (2, 4, 2))),
            Node("e", ("0", "1", "2"), ("d",), _random_cpt(rng, (2, 3))),
        ]
    )


def _brute_force(net: DiscreteBayesNet, query: str, evidence: dict[str, int]) -> np.ndarray:
    names = list(net.nodes)
    out = np.zeros(len(net.states(query)))
    for values in itertools.product(*(range(len(net.states(n))) for n in names)):
        v = dict(zip(names, values, strict=True))
        if any(v[k] != s for k, s in evidence.items()):
            continue
        p = 1.0
        for node in net.nodes.values():
            p *= node.cpt[(*tuple(v[q] for q in node.parents), v[node.name])]
        out[v[query]] += p
    return out / out.sum()


def test_queries_equal_brute_force_enumeration():
    net = _random_net(np.random.default_rng(4))
    for query, evidence in [("a", {"e": 2}), ("d", {"a": 1}), ("b", {"e": 0, "c": 3}), ("c", {})]:
        np.testing.assert_allclose(net.posterior(query, evidence), _brute_force(net, query, evidence), rtol=1e-12)
    table = net.posterior_table("a", ["e", "b"])
    assert table.shape == (3, 2, 3)
    for e, b in itertools.product(range(3), range(2)):
        np.testing.assert_allclose(table[e, b], _brute_force(net, "a", {"e": e, "b": b}), rtol=1e-12)


def test_burglary_network_textbook_value():
    """Pearl's alarm network (Russell & Norvig): P(burglary | John and Mary call) = 0.284."""
    t = ("false", "true")
    alarm = binary_cpt(np.array([[0.001, 0.29], [0.94, 0.95]]))  # [burglary, earthquake]
    net = DiscreteBayesNet(
        [
            Node("burglary", t, (), binary_cpt(0.001)),
            Node("earthquake", t, (), binary_cpt(0.002)),
            Node("alarm", t, ("burglary", "earthquake"), alarm),
            Node("john", t, ("alarm",), binary_cpt(np.array([0.05, 0.90]))),
            Node("mary", t, ("alarm",), binary_cpt(np.array([0.01, 0.70]))),
        ]
    )
    p = net.posterior("burglary", {"john": "true", "mary": "true"})[1]
    assert p == pytest.approx(0.2842, abs=5e-4)


def test_bad_networks_and_evidence_are_refused():
    with pytest.raises(ValueError, match="defined before"):
        DiscreteBayesNet([Node("b", ("0", "1"), ("a",), np.full((2, 2), 0.5))])
    with pytest.raises(ValueError, match="CPT shape"):
        DiscreteBayesNet([Node("a", ("0", "1"), (), np.full(3, 1 / 3))])
    with pytest.raises(ValueError, match="summing to 1"):
        DiscreteBayesNet([Node("a", ("0", "1"), (), np.array([0.5, 0.6]))])
    net = DiscreteBayesNet([Node("a", ("x", "y"), (), np.array([1.0, 0.0])), Node("b", ("0", "1"), ("a",), np.eye(2))])
    with pytest.raises(ValueError, match="no state"):
        net.posterior("b", {"a": "z"})
    with pytest.raises(ValueError, match="probability 0"):
        net.posterior("b", {"a": "y"})
    assert np.isnan(net.posterior_table("b", ["a"])[1]).all()
