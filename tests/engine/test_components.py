"""Connected components in Warp (engine/components.py): the partition scipy finds, each node at its component's
smallest node, and only the edges ranked up to a bound joining."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components as scipy_components

from engine import connected_components


def smallest_node_labels(n, a, b):
    """The reference: scipy's components, each labelled by its smallest node."""
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, labels = scipy_components(graph, directed=False)
    smallest = np.full(labels.max() + 1 if n else 0, n)
    np.minimum.at(smallest, labels, np.arange(n))
    return smallest[labels]


@pytest.mark.parametrize("seed", range(6))
def test_components_are_scipys_with_the_smallest_node_as_root(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4000))
    e = int(rng.integers(0, 2 * n))  # from many singletons to one giant component
    a, b = rng.integers(0, n, e), rng.integers(0, n, e)
    root = connected_components(n, a, b)
    assert root.shape == (n,)
    assert np.array_equal(root, smallest_node_labels(n, a, b))


def test_a_long_chain_in_reverse_order_is_one_component():
    # the worst order for hooking: every edge's larger end hooked under the next one down
    n = 20_000
    a = np.arange(n - 1)[::-1]
    root = connected_components(n, a, a + 1)
    assert np.array_equal(root, np.zeros(n))


def test_only_the_edges_ranked_up_to_the_bound_join():
    rng = np.random.default_rng(7)
    n = 3000
    a, b = rng.integers(0, n, 4000), rng.integers(0, n, 4000)
    rank = rng.integers(0, 4, 4000).astype(np.int32)
    for up_to in range(4):
        use = rank <= up_to
        root = connected_components(n, a, b, rank=rank, up_to=up_to)
        assert np.array_equal(root, smallest_node_labels(n, a[use], b[use])), up_to
