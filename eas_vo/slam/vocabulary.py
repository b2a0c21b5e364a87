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

import functools
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
            lines.append(
                f"{self.parent[i]} {int(self.is_leaf[i])} {' '.join(map(str, self.descriptors[i]))} {self.weight[i]:.9g}"
            )
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
        raise EasVoError(
            f"{len(everything)} ORB descriptors in the training images: a vocabulary with k={k} needs at least {k}"
        )
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
        raise DataError(
            path,
            f"header {line.strip()!r} out of DBoW2's ranges (k 0..{MAX_K}, L 1..{MAX_LEVELS}, "
            "scoring 0..5, weighting 0..3)",
            1,
        )
    return k, levels, scoring, weighting


#: Bytes of a text vocabulary parsed at once (whole lines): ORB-SLAM3's ORBvoc.txt (10^6 nodes)
#: is read in pieces of this size, each parsed by numpy, never as a Python list of its lines.
BLOCK_BYTES = 1 << 23
#: The characters of a number numpy's parser reads (digits, sign, point, exponent, nan, inf).
NUMBER_CHARACTERS = np.frombuffer(b"0123456789+-.eEnNaAiIfF", np.uint8)
WHITESPACE = np.frombuffer(b" \t\r\n\v\f", np.uint8)
FIELDS = DESCRIPTOR_BYTES + 3  # parent, is_leaf, the bytes, the weight


def _lines_of(path: Path):
    """(first line number, whole lines as bytes) of `path` after its header, BLOCK_BYTES at a
    time; the header line itself first, as (1, its bytes)."""
    try:
        with open(path, "rb") as fh:
            yield 1, fh.readline(200)
            number, rest = 2, b""
            while block := fh.read(BLOCK_BYTES):
                block = rest + block
                cut = block.rfind(b"\n") + 1
                if cut:
                    yield number, block[:cut]
                    number += block.count(b"\n", 0, cut)
                    rest = block[cut:]
                else:
                    rest = block
            yield number, rest  # the last line (empty after a final newline)
    except OSError as exc:
        raise DataError(path, f"cannot read as a text vocabulary: {exc.strerror or exc}") from None


def _nodes(path: Path, first: int, block: bytes, count: int):
    """parent, is_leaf, descriptors, weight of the nodes on the lines of `block` (line `first`
    on: node first - 1), checked: each line `parent is_leaf`, DESCRIPTOR_BYTES bytes and a
    weight; the parent an earlier node, is_leaf 0 or 1, the bytes whole numbers 0..255, the
    weight finite. `count`: the nodes read before (the root included)."""
    data = np.frombuffer(block, np.uint8)
    line_of = np.concatenate([[0], np.cumsum(data == ord("\n"))[:-1]])  # each byte's line in the block
    lines = block.count(b"\n") + (not block.endswith(b"\n"))
    space = np.isin(data, WHITESPACE)
    foreign = ~space & ~np.isin(data, NUMBER_CHARACTERS)
    if foreign.any():
        raise DataError(path, "a field is not a number", first + int(line_of[np.argmax(foreign)]))
    starts = ~space & np.concatenate([[True], space[:-1]])
    fields = np.bincount(line_of[starts], minlength=lines)
    wrong = np.flatnonzero(fields != FIELDS)
    if len(wrong):
        raise DataError(
            path,
            f"expected 'parent is_leaf' then {DESCRIPTOR_BYTES} descriptor bytes and a weight, "
            f"got {fields[wrong[0]]} fields",
            first + int(wrong[0]),
        )
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # numpy's word for a field it could not parse
        try:
            values = np.fromstring(block.decode("ascii"), sep=" ")
        except (DeprecationWarning, ValueError):
            values = None
    if values is None or len(values) != lines * FIELDS:
        raise DataError(path, "a field is not a number", first + (len(values) // FIELDS if values is not None else 0))
    table = values.reshape(lines, FIELDS)
    integers = table[:, :-1]
    node = count + np.arange(lines)
    bad = (
        (integers != np.round(integers)).any(1)
        | ~(table[:, 0] >= 0)
        | ~(table[:, 0] < node)
        | ~np.isin(table[:, 1], (0, 1))
        | ~((integers[:, 2:] >= 0) & (integers[:, 2:] <= 255)).all(1)
        | ~np.isfinite(table[:, -1])
    )
    if bad.any():
        raise DataError(
            path,
            "parent not an earlier node, is_leaf not 0/1, a byte not a whole number 0..255 or a weight not finite",
            first + int(np.argmax(bad)),
        )
    return (table[:, 0].astype(np.int64), table[:, 1] == 1, integers[:, 2:].astype(np.uint8), table[:, -1])


def _check_tree(path: Path, k: int, levels: int, parent: np.ndarray, is_leaf: np.ndarray) -> None:
    """The nodes form DBoW2's tree of k branches and `levels` levels: a node has children exactly
    when it is not a leaf (a file cut at a line's end leaves inner nodes without theirs), at most
    k, and no node lies deeper than `levels`. Node i is on line i + 1."""
    children = np.bincount(parent[1:], minlength=len(parent))
    if children[0] == 0:
        raise DataError(path, "holds no node but the root (the file ends after its header)", 2)
    childless = np.flatnonzero(~is_leaf[1:] & (children[1:] == 0)) + 1
    if len(childless):
        raise DataError(path, "an inner node (is_leaf 0) without children: the file ends early", int(childless[0]) + 1)
    under_leaf = np.flatnonzero(is_leaf[parent[1:]]) + 1
    if len(under_leaf):
        raise DataError(path, "the parent is a leaf (is_leaf 1)", int(under_leaf[0]) + 1)
    crowded = np.flatnonzero(children > k)
    if len(crowded):
        extra = np.flatnonzero(parent == crowded[0])[k]
        raise DataError(path, f"node {crowded[0]} gets more than the header's k = {k} children", int(extra) + 1)
    depth = np.zeros(len(parent), np.int64)
    for _ in range(levels + 1):  # parents come first: each pass settles one more level
        depth[1:] = depth[parent[1:]] + 1
    deep = np.flatnonzero(depth > levels)
    if len(deep):
        raise DataError(path, f"a node deeper than the header's L = {levels} levels", int(deep[0]) + 1)


def read_vocabulary(path: str | Path) -> Vocabulary:
    """A DBoW2 text vocabulary of ORB descriptors, every line and the tree's structure checked
    (_nodes, _check_tree); a malformed one is a DataError naming its line. A final newline (as
    DBoW2's saveToTextFile ends every line) is accepted; any other empty line is not. Parsed
    BLOCK_BYTES at a time by numpy, so ORB-SLAM3's 10^6-word ORBvoc.txt is read whole before
    ORB-SLAM3 would load it."""
    path = Path(path)
    pieces = _lines_of(path)
    _, header = next(pieces)
    try:
        k, levels, _, _ = _header(path, header.decode("ascii"))
    except UnicodeDecodeError:
        raise DataError(path, "cannot read as a text vocabulary: not ASCII text", 1) from None
    parts = [(np.array([-1]), np.array([False]), np.zeros((1, DESCRIPTOR_BYTES), np.uint8), np.zeros(1))]
    count = 1
    for first, block in pieces:
        if not block:  # nothing after the last line's newline
            continue
        part = _nodes(path, first, block, count)
        parts.append(part)
        count += len(part[0])
    parent, is_leaf, descriptors, weight = (np.concatenate(column) for column in zip(*parts))
    _check_tree(path, k, levels, parent, is_leaf)
    return Vocabulary(k, levels, parent, is_leaf, descriptors, weight)


@functools.lru_cache(maxsize=4)
def _checked(path: str, size: int, mtime_ns: int) -> None:
    read_vocabulary(path)


def check_vocabulary(path: str | Path) -> None:
    """read_vocabulary's checks of every line and of the tree, before ORB-SLAM3 loads `path`
    (its loader takes any file, exits on some and builds a broken tree of others); each file
    (path, size, modification time) checked once a process."""
    stat = Path(path).stat()
    _checked(str(path), stat.st_size, stat.st_mtime_ns)
