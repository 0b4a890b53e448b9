"""The committed study-file reference is the one generated from the models."""

from bayescal.config.reference import (
    documented_models,
    reachable_models,
    study_reference_markdown,
)
from paths import REPO

DOC = REPO / "docs" / "study-file.md"


def test_committed_reference_is_current() -> None:
    assert DOC.read_text(encoding="utf-8") == study_reference_markdown(), (
        "docs/study-file.md is stale: run "
        "`python -m bayescal.config.reference > docs/study-file.md`"
    )


def test_every_section_documents_every_key() -> None:
    text = study_reference_markdown()
    for key in ("time_zone", "max_gap_interpolate", "targets", "test_samples", "solar_absorptance"):
        assert f"| `{key}` |" in text
    assert "0x" not in text  # no object addresses: the text is deterministic


def test_every_table_a_study_can_hold_has_a_section() -> None:
    # a model reachable from Study (a [[data.exclude]] window, a [derived.NAME] table, a
    # prior) without a section would leave its keys undocumented
    missing = sorted(m.__name__ for m in reachable_models() - documented_models())
    assert not missing, f"no section of docs/study-file.md for {missing}"
    text = study_reference_markdown()
    for key in ("reason", "columns", "expression", "prior_from"):
        assert f"| `{key}` |" in text
