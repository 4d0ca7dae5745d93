import numpy as np

from icrsumo.learn.text import TextEncoder, build_vocab, ngrams, words


def test_words_lowercase_and_numbers():
    assert words("In 80 meters, Turn LEFT.") == ["in", "<num>", "meters", "turn", "left"]


def test_vocab_is_deterministic_and_ordered_by_count():
    v = build_vocab(["turn left", "turn right", "go straight"])
    assert v[:3] == ["<pad>", "<unk>", "turn"]
    assert v == build_vocab(["go straight", "turn right", "turn left"])


def test_token_encoder_pads_and_maps_unknown():
    vocab = tuple(build_vocab(["turn left now"]))
    enc = TextEncoder("token", 6, vocab)
    ids = enc.encode("Turn right now")
    assert ids.dtype == np.int64 and ids.shape == (6,)
    assert ids[1] == 1 and ids[0] == vocab.index("turn") and (ids[3:] == 0).all()


def test_ngram_encoder_shares_ngrams_across_typos():
    enc = TextEncoder("ngram", 64, buckets=4096)
    a = set(enc.encode("turn left at the intersection")) - {0}
    b = set(enc.encode("turn left at the intersectoin")) - {0}
    assert len(a & b) / len(a | b) > 0.6
    assert min(a) > 0 and max(a) < 4096
    assert ngrams("left")[:2] == ["<left>", "<le"]
    np.testing.assert_array_equal(enc.encode("turn left"), enc.encode("turn left"))
