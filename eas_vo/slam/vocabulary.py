"""DBoW2 vocabularies of ORB descriptors, as ORB-SLAM loads them: trained by hierarchical
k-majority clustering on Hamming distance (DBoW2's HKmeansStep with k-means++ seeding and the
bitwise majority as the cluster centre), word weights by inverse document frequency (TF-IDF),
written and read in DBoW2's text format.

The text format (TemplatedVocabulary::loadFromTextFile): a header line `k L scoring weighting`
(scoring 0 = L1 norm, weighting 0 = TF-IDF), then one line per node but the root, in id order
(node i + 1 on line i + 2): `parent_id is_leaf d_0 ... d_31 weight`, the 32 descriptor bytes in
decimal. No newline after the last line: the loader reads an empty last line as a node.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eas_vo.errors import DataError, EasVoError

DESCRIPTOR_BYTES = 32  # ORB: 256 bits
SCORING_L1, WEIGHTING_TF_IDF = 0, 0
#: DBoW2's loader refuses k outside 0..20 and L outside 1..10.
MAX_K, MAX_LEVELS = 20, 10
#: Lloyd iterations per k-majority step at most (DBoW2 iterates to convergence; k-majority
#: converges in a handful on ORB descriptors, and the cap bounds a pathological set).
MAX_ITERATIONS = 30
#: Descriptors clustered at most (a seeded random subset beyond; every image still counts for
#: the weights): a minute of 240x180 images holds ~10^6, more than 10^4 words need.
MAX_CLUSTERED = 200_000


@dataclass(frozen=True)
class Vocabulary:
    """A vocabulary tree. Node 0 is the root; node i has `parent[i]`, descriptor
    `descriptors[i]` (32 bytes) and `weight[i]` (the IDF of a leaf, a word; 0 for inner nodes)."""

    k: int
    levels: int
    parent: np.ndarray  # (n,) int64, parent[0] = -1
    is_leaf: np.ndarray  # (n,) bool
    descriptors: np.ndarray  # (n, 32) uint8
    weight: np.ndarray  # (n,) float64

    @property
    def words(self) -> int:
        return int(self.is_leaf.sum())

    def text(self) -> str:
        """The vocabulary in DBoW2's text format (module docstring)."""
        lines = [f"{self.k} {self.levels} {SCORING_L1} {WEIGHTING_TF_IDF}"]
        for i in range(1, len(self.parent)):
            lines.append(f"{self.parent[i]} {int(self.is_leaf[i])} {' '.join(map(str, self.descriptors[i]))} {self.weight[i]:.9g}")
        return "\n".join(lines)

    def children(self) -> np.ndarray:
        """(n, k) child ids per node, -1 where there is none."""
        table = np.full((len(self.parent), self.k), -1, np.int64)
        count = np.zeros(len(self.parent), np.int64)
        for i in range(1, len(self.parent)):
            p = self.parent[i]
            table[p, count[p]] = i
            count[p] += 1
        return table

    def words_of(self, descriptors: np.ndarray) -> np.ndarray:
        """The node id of the word each descriptor (m, 32) falls in, descending the tree by the
        nearest child in Hamming distance as DBoW2's transform does."""
        children = self.children()
        packed = _as_words64(self.descriptors)
        query = _as_words64(np.ascontiguousarray(descriptors, np.uint8))
        node = np.zeros(len(query), np.int64)
        for _ in range(self.levels):
            cand = children[node]  # (m, k)
            inner = cand[:, 0] >= 0
            if not inner.any():
                break
            c = cand[inner]
            d = np.bitwise_count(query[inner, None, :] ^ packed[np.maximum(c, 0)]).sum(-1).astype(np.int64)
            d[c < 0] = np.iinfo(np.int64).max
            node[inner] = c[np.arange(len(c)), d.argmin(1)]
        return node


def _as_words64(descriptors: np.ndarray) -> np.ndarray:
    """(n, 32) uint8 -> (n, 4) uint64, for XOR and popcount."""
    return np.ascontiguousarray(descriptors).view(np.uint64).reshape(len(descriptors), DESCRIPTOR_BYTES // 8)


def hamming(a64: np.ndarray, b64: np.ndarray) -> np.ndarray:
    """Hamming distances [bits] (n, m) between packed descriptors a (n, 4) and b (m, 4) uint64."""
    return np.bitwise_count(a64[:, None, :] ^ b64[None, :, :]).sum(-1, dtype=np.int64)


def majority(descriptors: np.ndarray) -> np.ndarray:
    """The bitwise majority (32,) uint8 of descriptors (m, 32): a bit is set when at least half
    of them (rounded up) have it, as DBoW2's FORB::meanValue."""
    bits = np.unpackbits(descriptors, axis=1).sum(0, dtype=np.int64)
    return np.packbits(bits >= (len(descriptors) + 1) // 2)


def k_majority(descriptors: np.ndarray, k: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Split descriptors (m, 32) into at most k clusters: k-means++ seeding (a seed drawn with
    probability proportional to its squared distance from the nearest seed so far: Arthur and
    Vassilvitskii's rule; DBoW2 weights by the distance itself, which seeds two centres in one
    tight group more often), then
    assignment to the nearest centre and majority centres until no assignment changes.
    Returns the members' row indices of each non-empty cluster; m <= k, or fewer than k
    distinct descriptors, gives one cluster per distinct descriptor."""
    unique, inverse = np.unique(descriptors, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    if len(unique) <= k:
        return [np.flatnonzero(inverse == u) for u in range(len(unique))]
    packed = _as_words64(descriptors)
    centres = [packed[rng.integers(len(packed))]]
    nearest = hamming(packed, centres[0][None])[:, 0]
    while len(centres) < k:
        square = nearest.astype(np.float64) ** 2
        pick = rng.choice(len(packed), p=square / square.sum())
        centres.append(packed[pick])
        nearest = np.minimum(nearest, hamming(packed, packed[pick][None])[:, 0])
    centres = np.stack(centres)
    assignment = None
    for _ in range(MAX_ITERATIONS):
        new = hamming(packed, centres).argmin(1)
        if assignment is not None and np.array_equal(new, assignment):
            break
        assignment = new
        for c in range(k):
            members = assignment == c
            if members.any():
                centres[c] = _as_words64(majority(descriptors[members])[None])[0]
    return [np.flatnonzero(assignment == c) for c in range(k) if (assignment == c).any()]


def check_shape(k: int, levels: int) -> None:
    """One line unless DBoW2 loads a tree of k branches and L levels."""
    if not 2 <= k <= MAX_K or not 1 <= levels <= MAX_LEVELS:
        raise EasVoError(f"vocabulary k={k}, L={levels}: DBoW2 takes k in 2..{MAX_K} and L in 1..{MAX_LEVELS}")


def train(descriptor_sets: list[np.ndarray], k: int = 10, levels: int = 4, seed: int = 0) -> Vocabulary:
    """A vocabulary of k branches and `levels` levels from the ORB descriptors of training
    images (one (m_i, 32) uint8 array per image); word weights log(N / N_w), N images, N_w of
    them holding a descriptor of word w (DBoW2's IDF; 0 for a word no image holds). Seeded:
    the same images and seed give the same vocabulary."""
    check_shape(k, levels)
    sets = [np.ascontiguousarray(d, np.uint8).reshape(-1, DESCRIPTOR_BYTES) for d in descriptor_sets]
    everything = np.concatenate(sets) if sets else np.empty((0, DESCRIPTOR_BYTES), np.uint8)
    if len(everything) < k:
        raise EasVoError(f"{len(everything)} ORB descriptors in the training images: a vocabulary with k={k} needs at least {k}")
    rng = np.random.default_rng(seed)
    if len(everything) > MAX_CLUSTERED:
        everything = everything[np.sort(rng.choice(len(everything), MAX_CLUSTERED, replace=False))]
    parent, descriptors = [-1], [np.zeros(DESCRIPTOR_BYTES, np.uint8)]
    queue = [(0, np.arange(len(everything)), 1)]  # (node, its descriptors' rows, level of its children)
    has_children = set()
    while queue:
        node, rows, level = queue.pop(0)
        has_children.add(node)
        for members in k_majority(everything[rows], k, rng):
            child = len(parent)
            parent.append(node)
            descriptors.append(majority(everything[rows[members]]))
            held = everything[rows[members]]
            if level < levels and (held != held[0]).any():  # more than one distinct descriptor to split
                queue.append((child, rows[members], level + 1))
    parent = np.array(parent, np.int64)
    is_leaf = np.ones(len(parent), bool)
    is_leaf[list(has_children)] = False
    tree = Vocabulary(k, levels, parent, is_leaf, np.stack(descriptors), np.zeros(len(parent)))
    holding = np.zeros(len(parent), np.int64)
    for d in sets:
        if len(d):
            holding[np.unique(tree.words_of(d))] += 1
    weight = np.where(is_leaf & (holding > 0), np.log(len(sets) / np.maximum(holding, 1)), 0.0)
    return Vocabulary(k, levels, parent, is_leaf, tree.descriptors, weight)


def _header(path: Path, line: str) -> tuple[int, int, int, int]:
    """k, L, scoring, weighting of a header line, checked against DBoW2's ranges."""
    head = line.split()
    if len(head) != 4 or not all(v.isdigit() for v in head):
        raise DataError(path, "expected the header 'k L scoring weighting' (DBoW2's text vocabulary)", 1)
    k, levels, scoring, weighting = map(int, head)
    if not (0 <= k <= MAX_K and 1 <= levels <= MAX_LEVELS and 0 <= scoring <= 5 and 0 <= weighting <= 3):
        raise DataError(path, f"header {line.strip()!r} out of DBoW2's ranges (k 0..{MAX_K}, L 1..{MAX_LEVELS}, "
                        "scoring 0..5, weighting 0..3)", 1)
    return k, levels, scoring, weighting


def check_header(path: str | Path) -> None:
    """The first line of a text vocabulary checked (the rest of a 139 MB ORBvoc.txt is left to
    ORB-SLAM3): a binary or foreign file is a one-line error before ORB-SLAM3 exits on it."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            first = fh.readline(200).decode("ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(path, f"cannot read as a text vocabulary: {getattr(exc, 'strerror', None) or exc}") from None
    _header(path, first)


def read_vocabulary(path: str | Path) -> Vocabulary:
    """A DBoW2 text vocabulary of ORB descriptors; a malformed one is a DataError naming its line."""
    path = Path(path)
    try:
        lines = path.read_text().split("\n")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(path, f"cannot read as a text vocabulary: {getattr(exc, 'strerror', None) or exc}") from None
    k, levels, _, _ = _header(path, lines[0])
    parent, is_leaf, descriptors, weight = [-1], [False], [np.zeros(DESCRIPTOR_BYTES, np.uint8)], [0.0]
    for number, line in enumerate(lines[1:], start=2):
        fields = line.split()
        if len(fields) != DESCRIPTOR_BYTES + 3:
            raise DataError(path, f"expected 'parent is_leaf' then {DESCRIPTOR_BYTES} descriptor bytes and a weight, "
                            f"got {len(fields)} fields", number)
        try:
            p, leaf, *data = (int(v) for v in fields[:-1])
            w = float(fields[-1])
        except ValueError:
            raise DataError(path, "a field is not a number", number) from None
        if not 0 <= p < len(parent) or leaf not in (0, 1) or not all(0 <= b <= 255 for b in data) or not np.isfinite(w):
            raise DataError(path, "parent not an earlier node, is_leaf not 0/1, a byte outside 0..255 or a weight not finite", number)
        parent.append(p)
        is_leaf.append(bool(leaf))
        descriptors.append(np.array(data, np.uint8))
        weight.append(w)
    return Vocabulary(k, levels, np.array(parent, np.int64), np.array(is_leaf), np.stack(descriptors), np.array(weight))
