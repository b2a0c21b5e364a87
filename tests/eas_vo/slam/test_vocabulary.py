"""DBoW2 vocabularies: the k-majority maths against exact answers and OpenCV's Hamming norm,
the tree's shape, the IDF weights, and the text format read back."""

import re

import cv2
import numpy as np
import pytest

from eas_vo.errors import DataError, EasVoError
from eas_vo.slam.vocabulary import _as_words64, check_vocabulary, hamming, k_majority, majority, read_vocabulary, train


def random_descriptors(rng, n):
    return rng.integers(0, 256, (n, 32), dtype=np.uint8)


def flipped(rng, centre, n, bits):
    """n copies of `centre` (32,) uint8, each with `bits` distinct random bits flipped."""
    out = np.unpackbits(np.repeat(centre[None], n, 0), axis=1)
    for row in out:
        row[rng.choice(256, bits, replace=False)] ^= 1
    return np.packbits(out, axis=1)


def test_hamming_is_opencvs_norm():
    rng = np.random.default_rng(0)
    a, b = random_descriptors(rng, 7), random_descriptors(rng, 5)
    expected = np.array([[cv2.norm(x, y, cv2.NORM_HAMMING) for y in b] for x in a])
    np.testing.assert_array_equal(hamming(_as_words64(a), _as_words64(b)), expected)


def test_majority_sets_a_bit_held_by_at_least_half():
    rows = np.zeros((4, 32), np.uint8)
    rows[:2, 0] = 0b1000_0000  # two of four: half, set (DBoW2 rounds half up)
    rows[:1, 1] = 0b0000_0001  # one of four: not set
    rows[:, 31] = 0xFF
    expected = np.zeros(32, np.uint8)
    expected[0], expected[31] = 0b1000_0000, 0xFF
    np.testing.assert_array_equal(majority(rows), expected)


def test_k_majority_recovers_well_separated_clusters():
    """Four centres ~128 bits apart, 50 members each within 10 bits: the clusters are the groups."""
    rng = np.random.default_rng(1)
    centres = random_descriptors(rng, 4)
    data = np.concatenate([flipped(rng, c, 50, 10) for c in centres])
    clusters = k_majority(data, 4, np.random.default_rng(2))
    assert sorted(sorted(set(c // 50)) for c in clusters) == [[0], [1], [2], [3]]
    assert sorted(len(c) for c in clusters) == [50] * 4


def test_k_majority_of_fewer_distinct_descriptors_than_k_is_one_cluster_each():
    rng = np.random.default_rng(3)
    data = np.repeat(random_descriptors(rng, 3), [2, 1, 4], axis=0)
    clusters = k_majority(data, 10, rng)
    assert sorted(len(c) for c in clusters) == [1, 2, 4]


def test_a_full_tree_has_sum_of_k_to_the_l_nodes_and_reads_back(tmp_path):
    rng = np.random.default_rng(4)
    images = [random_descriptors(rng, 400) for _ in range(10)]
    vocabulary = train(images, k=5, levels=3, seed=0)
    path = tmp_path / "voc.txt"
    path.write_text(vocabulary.text())
    text = path.read_text()
    assert text.split("\n")[0] == "5 3 0 0" and not text.endswith("\n")  # L1 scoring, TF-IDF; no empty last line
    back = read_vocabulary(path)
    assert len(back.parent) - 1 == 5 + 5**2 + 5**3
    assert back.words == 5**3 and back.descriptors.shape == (len(back.parent), 32)
    assert np.isfinite(back.weight).all() and (back.weight[back.is_leaf] >= 0).all()
    assert (back.weight[~back.is_leaf] == 0).all()
    np.testing.assert_array_equal(back.parent, vocabulary.parent)
    np.testing.assert_array_equal(back.descriptors, vocabulary.descriptors)
    np.testing.assert_allclose(back.weight, vocabulary.weight, rtol=1e-8)


def test_weights_are_the_inverse_document_frequency():
    """Two words: one in all four images (weight log 1 = 0), one in one image (log 4)."""
    rng = np.random.default_rng(5)
    a, b = random_descriptors(rng, 2)
    images = [flipped(rng, a, 5, 3) for _ in range(4)]
    images[0] = np.concatenate([images[0], flipped(rng, b, 5, 3)])
    vocabulary = train(images, k=2, levels=1, seed=0)
    words = vocabulary.words_of(np.stack([a, b]))
    np.testing.assert_allclose(vocabulary.weight[words], [0.0, np.log(4.0)])


def test_training_is_seeded():
    rng = np.random.default_rng(6)
    images = [random_descriptors(rng, 300) for _ in range(3)]
    assert train(images, 4, 2, seed=7).text() == train(images, 4, 2, seed=7).text()


def test_too_few_descriptors_or_a_k_dbow2_refuses_is_one_line():
    with pytest.raises(EasVoError, match="needs at least 10"):
        train([np.zeros((3, 32), np.uint8)], k=10, levels=2)
    with pytest.raises(EasVoError, match="k in 2..20"):
        train([np.zeros((30, 32), np.uint8)], k=21, levels=2)


@pytest.mark.parametrize(
    "text, line, what",
    [
        ("10 4 0\n", 1, "header"),
        ("10 11 0 0\n0 1 " + "0 " * 32 + "0", 1, "ranges"),
        ("10 4 0 0\n0 1 " + "0 " * 31 + "0", 2, "fields"),
        ("10 4 0 0\n3 1 " + "0 " * 32 + "0", 2, "earlier node"),
        ("10 4 0 0\n0 1 " + "0 " * 32 + "nan", 2, "finite"),
        ("10 4 0 0\n0 1 " + "256 " * 32 + "0", 2, "0..255"),
    ],
)
def test_a_malformed_vocabulary_names_its_line(tmp_path, text, line, what):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(DataError, match=what) as info:
        read_vocabulary(path)
    assert str(info.value).startswith(f"{path}:{line}: ")


def test_check_vocabulary_refuses_a_binary_file(tmp_path):
    path = tmp_path / "ORBvoc.bin"
    path.write_bytes(b"\x00\xff\x10binary")
    with pytest.raises(DataError, match="text vocabulary"):
        check_vocabulary(path)


@pytest.fixture(scope="module")
def small_text():
    """A trained vocabulary in the text format: k = 5, L = 2, full (the 5 inner nodes on lines
    2-6, then their 5 leaves each on lines 7-31, in DBoW2's breadth-first order)."""
    rng = np.random.default_rng(7)
    vocabulary = train([random_descriptors(rng, 200) for _ in range(4)], k=5, levels=2, seed=0)
    assert vocabulary.parent.tolist() == [-1] + [0] * 5 + [p for p in range(1, 6) for _ in range(5)]
    return vocabulary.text()


def _replace_line(text, line, new):
    lines = text.split("\n")
    lines[line - 1] = new
    return "\n".join(lines)


BROKEN = {  # name: (damage of the text, the line named ("last": the damaged file's last), what the message says)
    "64-byte descriptors": (lambda t: _replace_line(t, 3, "0 0 " + "7 " * 64 + "0"), 3, "got 67 fields"),
    "a byte above 255": (lambda t: _replace_line(t, 4, "0 0 " + "300 " * 32 + "0"), 4, "0..255"),
    "a NaN weight": (lambda t: t.rsplit(" ", 1)[0] + " nan", 31, "not finite"),
    "cut in half inside a line": (lambda t: t[: len(t) // 2], "last", "fields"),
    "cut in half after a line": (lambda t: "\n".join(t.split("\n")[:16]), 4, "inner node .* without children"),
    "a child of a leaf": (lambda t: _replace_line(t, 9, "6 1 " + "0 " * 32 + "0.5"), 9, "parent is a leaf"),
    "a sixth child": (lambda t: _replace_line(t, 12, "1 1 " + "0 " * 32 + "0.5"), 12, "more than the header's k = 5"),
    "a third level": (lambda t: t.replace("5 2 0 0", "5 1 0 0", 1), 7, "deeper than the header's L = 1"),
    "an empty line": (lambda t: _replace_line(t, 9, ""), 9, "got 0 fields"),
    "a word that is not a number": (lambda t: _replace_line(t, 5, "0 0 " + "x " * 32 + "0"), 5, "not a number"),
}


@pytest.mark.parametrize("name", BROKEN)
def test_a_broken_vocabulary_is_refused_naming_its_line(tmp_path, small_text, name):
    damage, line, what = BROKEN[name]
    path = tmp_path / "bad.txt"
    damaged = damage(small_text)
    path.write_text(damaged)
    line = damaged.count("\n") + 1 if line == "last" else line
    with pytest.raises(DataError, match=what) as info:
        check_vocabulary(path)
    message = str(info.value)
    assert re.match(rf"{re.escape(str(path))}:{line}: ", message) and "\n" not in message


def test_the_numbers_of_every_line_are_read_back_and_a_final_newline_is_accepted(tmp_path, small_text):
    """Every node of a file parsed in pieces of a few lines reads back as written."""
    from eas_vo.slam import vocabulary

    path = tmp_path / "voc.txt"
    path.write_text(small_text + "\n")  # DBoW2's saveToTextFile ends every line with one
    whole = read_vocabulary(path)
    assert whole.text() == small_text
    try:
        vocabulary.BLOCK_BYTES, saved = 300, vocabulary.BLOCK_BYTES  # pieces of 2-3 lines
        assert read_vocabulary(path).text() == small_text
    finally:
        vocabulary.BLOCK_BYTES = saved
