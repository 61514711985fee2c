"""The friction kernel's generated source: its loop bodies come from kernel_ir's intrinsics, so the text numba types
does not grow with the press's loop structure, and a changed emitter is a new file for numba's disk cache."""
import numpy as np
import pytest

from press_model import batch_kernel as BK


def _structure(r: int, n_lam: int) -> np.ndarray:
    """A +-1 matrix G of the shape of r reactions and n_lam loop-force components (the values do not matter here)."""
    return np.where(np.arange((2 * r - 1) * n_lam).reshape(2 * r - 1, n_lam) % 3 == 0, 1.0, 0.0)


def test_kernel_text_does_not_grow_with_the_loop_structure():
    """numba typed and lowered each operation of the written-out pass on its own (~18 s of CPU for the reference
    press's 10 reactions, ~5 s for the crank-slider's): the Python text of the kernel is now its loops alone."""
    small = BK.kernel_text(_structure(2, 1), 2, 3, 8).splitlines()
    large = BK.kernel_text(_structure(10, 6), 10, 22, 8).splitlines()
    assert len(small) == len(large), (len(small), len(large))
    assert max(map(len, large)) < 1500  # the structure's G on one line, no written-out operation


def test_a_changed_emitter_is_a_new_kernel_file(monkeypatch):
    """numba's disk cache is keyed by the generated file alone, whose name is the digest of its text: the text holds
    kernel_ir.py's digest, so machine code from an older emitter is never loaded for a newer one."""
    G = _structure(3, 2)
    before = BK.kernel_text(G, 3, 5, 8)
    monkeypatch.setattr(BK, "_emitter_digest", lambda: "0123456789abcdef")
    after = BK.kernel_text(G, 3, 5, 8)
    assert before != after and "0123456789abcdef" in after


@pytest.mark.parametrize("lanes", [3, 7])
def test_odd_lanes_are_refused(lanes):
    with pytest.raises(ValueError, match="odd"):
        BK.kernel_text(_structure(2, 1), 2, 3, lanes)
