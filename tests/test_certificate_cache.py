"""The on-disk cache of LQR certificates (:func:`leoc.control.certify_lqr`).

A "new process" is the in-process cache cleared. The mountain car's certificate is the real one
(about 4 s, proved); where a test only needs the cache's bookkeeping, ``certify_level`` is
replaced by a stand-in that returns that certificate and counts its calls.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from leoc.control import design_lqr, roa
from leoc.systems.registry import make_system

SYSTEM = "mountaincar"


@pytest.fixture(scope="module")
def mountaincar():
    system = make_system(SYSTEM)
    return system, design_lqr(system)


@pytest.fixture(scope="module")
def reference(mountaincar):
    """The certificate computed without any cache."""
    system, design = mountaincar
    return roa.certify_level(
        system, design.P, roa.lqr_closed_loop(design), action_repeat=design.action_repeat
    )


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache folder and a fresh process cache; the folder of the certificates."""
    monkeypatch.setenv(roa.CACHE_DIR_VARIABLE, str(tmp_path))
    roa._CERTIFICATES.clear()
    yield tmp_path / roa.CERTIFICATE_FOLDER
    roa._CERTIFICATES.clear()


class _Counted:
    """Stand-in for ``certify_level``: counts calls, returns ``result`` (or the real one)."""

    def __init__(self, result=None):
        self.calls = 0
        self.result = result
        self.real = roa.certify_level

    def __call__(self, *args, **kwargs):
        self.calls += 1
        self.controller = args[2]  # certify_level(system, P, controller, ...)
        return self.real(*args, **kwargs) if self.result is None else self.result


def _refuse(*args, **kwargs):
    raise AssertionError("certify_level was called: the stored certificate was not used")


def _assert_same(certificate, expected) -> None:
    assert certificate.rho == expected.rho
    assert certificate.sampled_rho == expected.sampled_rho
    np.testing.assert_array_equal(certificate.P, expected.P)
    assert certificate.proof.rho == expected.proof.rho
    assert certificate.proof.limited_by == expected.proof.limited_by


def _key(mountaincar, **options) -> str:
    system, design = mountaincar
    return roa._certificate_key(system, design, options)


def _cache_file(mountaincar, cache) -> Path:
    """The cache file of the mountain car's certificate, its folder made."""
    path = cache / f"{_key(mountaincar)}.pkl"
    path.parent.mkdir(parents=True)
    return path


def test_a_second_process_loads_the_certificate_without_proving(
    mountaincar, reference, cache, monkeypatch
) -> None:
    system, design = mountaincar
    counted = _Counted()
    monkeypatch.setattr(roa, "certify_level", counted)
    first = roa.certify_lqr(system, design)
    assert counted.calls == 1
    assert [path.name for path in cache.iterdir()] == [f"{_key(mountaincar)}.pkl"]
    _assert_same(first, reference)
    roa._CERTIFICATES.clear()  # a new process
    monkeypatch.setattr(roa, "certify_level", _refuse)
    second = roa.certify_lqr(system, design)
    _assert_same(second, first)
    assert second.proof.seconds == first.proof.seconds  # the very same proof, not a new one


@pytest.mark.parametrize(
    "content",
    [
        b"\x00garbage, not a pickle\xff" * 10,
        b"",
        "truncated",
        pickle.dumps({"rho": 1.0e9}),
        pickle.dumps((1.0e9, "a tuple, not a certificate")),
    ],
    ids=["garbage", "empty", "truncated", "dict", "tuple"],
)
def test_a_file_that_does_not_load_is_recomputed_and_rewritten(
    mountaincar, reference, cache, monkeypatch, content
) -> None:
    system, design = mountaincar
    path = _cache_file(mountaincar, cache)
    if content == "truncated":
        content = pickle.dumps(reference)[:-40]
    path.write_bytes(content)
    counted = _Counted(reference)
    monkeypatch.setattr(roa, "certify_level", counted)
    _assert_same(roa.certify_lqr(system, design), reference)
    assert counted.calls == 1
    _assert_same(roa._load_certificate(path), reference)  # rewritten whole
    assert [item.name for item in cache.iterdir()] == [path.name]  # no temporary file left


@pytest.mark.slow
def test_a_corrupt_file_gives_the_fresh_certificate(
    mountaincar, reference, cache, monkeypatch
) -> None:
    """The real proof, run again on a corrupt file, equals the certificate without a cache."""
    system, design = mountaincar
    path = _cache_file(mountaincar, cache)
    path.write_bytes(b"\x80\x05corrupt" + bytes(range(256)))
    counted = _Counted()
    monkeypatch.setattr(roa, "certify_level", counted)
    _assert_same(roa.certify_lqr(system, design), reference)
    assert counted.calls == 1


def test_off_writes_nothing_and_reads_nothing(
    mountaincar, reference, cache, monkeypatch, tmp_path
) -> None:
    system, design = mountaincar
    path = _cache_file(mountaincar, cache)
    path.write_bytes(pickle.dumps(reference._replace(rho=123.0)))
    monkeypatch.setenv(roa.CACHE_DIR_VARIABLE, roa.CACHE_OFF)
    assert roa.certificate_cache_dir() is None
    counted = _Counted(reference)
    monkeypatch.setattr(roa, "certify_level", counted)
    assert roa.certify_lqr(system, design).rho == reference.rho  # the file is not read
    assert counted.calls == 1
    assert [item.name for item in cache.iterdir()] == [path.name]
    assert sorted(item.name for item in tmp_path.iterdir()) == [roa.CERTIFICATE_FOLDER]
    assert not (tmp_path / roa.CACHE_OFF).exists()


def test_changed_proof_code_makes_a_new_key(mountaincar, reference, cache, monkeypatch) -> None:
    system, design = mountaincar
    monkeypatch.setattr(roa, "certify_level", _Counted(reference))
    roa.certify_lqr(system, design)
    old = _key(mountaincar)
    assert [item.name for item in cache.iterdir()] == [f"{old}.pkl"]
    roa._CERTIFICATES.clear()
    monkeypatch.setattr(roa, "_source_digest", lambda: "the proof was edited")
    assert _key(mountaincar) != old
    counted = _Counted(reference._replace(rho=1.0))
    monkeypatch.setattr(roa, "certify_level", counted)
    assert roa.certify_lqr(system, design).rho == 1.0  # computed again, the old file unused
    assert counted.calls == 1
    assert sorted(item.name for item in cache.iterdir()) == sorted(
        [f"{old}.pkl", f"{_key(mountaincar)}.pkl"]
    )


def test_the_source_digest_covers_the_proof_modules(monkeypatch) -> None:
    digest = roa._source_digest()
    assert len(digest) == 64
    for name in roa.PROOF_MODULES:
        assert roa._module_digest(name) is not None, name
    monkeypatch.setattr(roa, "_module_digest", lambda name: f"edited {name}")
    assert roa._source_digest.__wrapped__() != digest
    monkeypatch.undo()
    assert roa._source_digest.__wrapped__() == digest


def test_another_design_gets_another_file(mountaincar, reference, cache, monkeypatch) -> None:
    system, design = mountaincar
    monkeypatch.setattr(roa, "certify_level", _Counted(reference))
    roa.certify_lqr(system, design)
    scaled = design_lqr(system, Q=2.0 * np.asarray(design.Q))
    counted = _Counted(reference._replace(rho=2.0))
    monkeypatch.setattr(roa, "certify_level", counted)
    assert roa.certify_lqr(system, scaled).rho == 2.0
    assert counted.calls == 1
    keys = {roa._certificate_key(system, item, {}) for item in (design, scaled)}
    assert sorted(item.stem for item in cache.iterdir()) == sorted(keys)
    assert len(keys) == 2


def test_an_unwritable_folder_is_skipped(mountaincar, reference, tmp_path, monkeypatch) -> None:
    system, design = mountaincar
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(roa.CACHE_DIR_VARIABLE, str(blocker))
    roa._CERTIFICATES.clear()
    counted = _Counted(reference)
    monkeypatch.setattr(roa, "certify_level", counted)
    _assert_same(roa.certify_lqr(system, design), reference)  # no error
    assert counted.calls == 1
    roa._CERTIFICATES.clear()


def test_the_default_folder(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(roa.CACHE_DIR_VARIABLE, "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert roa.certificate_cache_dir() == tmp_path / "leoc" / roa.CERTIFICATE_FOLDER
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    expected = tmp_path / "home" / ".cache" / "leoc" / roa.CERTIFICATE_FOLDER
    assert roa.certificate_cache_dir() == expected
    monkeypatch.setenv(roa.CACHE_DIR_VARIABLE, str(tmp_path / "mine"))
    assert roa.certificate_cache_dir() == tmp_path / "mine" / roa.CERTIFICATE_FOLDER


@pytest.mark.slow
def test_a_saturated_lqr_is_cached_under_its_own_key_and_proved_the_same(
    mountaincar, cache, monkeypatch
) -> None:
    """PILCO's hybrid certifies ``sin(G)``, not the clipped ``G``: leoc.policies.lqr_certificate
    caches it too, under a key of its saturation and limit, and the cached certificate is the
    one certify_level proves for that closed loop without any cache."""
    from leoc.policies.hybrid import lqr_certificate, saturated_lqr

    system, design = mountaincar
    expected = roa.certify_level(
        system,
        design.P,
        saturated_lqr(system, design, "sin"),
        action_repeat=design.action_repeat,
    )
    counted = _Counted()
    monkeypatch.setattr(roa, "certify_level", counted)
    first = lqr_certificate(system, design, "sin")
    _assert_same(first, expected)
    assert counted.calls == 1
    # the loop proved is sin(G), not the clipped G (the mountain car proves the same level for
    # both, limited by its region, so the level alone would not tell): compared where G is
    # beyond the limit, where sin and clip differ
    observations = torch.as_tensor(
        np.asarray(system.operating_obs) + np.linspace(-3.0, 3.0, 7)[:, None], dtype=torch.float64
    )
    with torch.no_grad():
        proved = counted.controller(observations)
        sine = saturated_lqr(system, design, "sin")(observations)
        clipped = roa.lqr_closed_loop(design)(observations).clamp(
            -system.action_limit, system.action_limit
        )
    torch.testing.assert_close(proved, sine, rtol=0, atol=1e-12)
    assert (proved - clipped).abs().max() > 1e-3
    assert len(list(cache.iterdir())) == 1
    roa._CERTIFICATES.clear()  # a new process
    monkeypatch.setattr(roa, "certify_level", _refuse)
    _assert_same(lqr_certificate(system, design, "sin"), expected)
    # another saturation or limit is another closed loop: proved, not read from sin's file
    monkeypatch.setattr(roa, "certify_level", counted)
    lqr_certificate(system, design, "tanh")
    lqr_certificate(system, design, "sin", action_limit=0.5 * system.action_limit)
    assert counted.calls == 3
    assert len(list(cache.iterdir())) == 3
    # and the clipped design's own certificate has a key of its own
    lqr_certificate(system, design, "clip")
    assert counted.calls == 4


@pytest.mark.slow
def test_a_controller_without_a_key_is_proved_at_every_call(mountaincar, cache, monkeypatch):
    """A controller certify_lqr cannot name (no controller_key) is never served from a cache:
    two calls, two proofs, nothing written."""
    system, design = mountaincar
    counted = _Counted()
    monkeypatch.setattr(roa, "certify_level", counted)
    controller = roa.lqr_closed_loop(design)
    roa.certify_lqr(system, design, controller)
    roa.certify_lqr(system, design, controller)
    assert counted.calls == 2
    assert not cache.exists()
