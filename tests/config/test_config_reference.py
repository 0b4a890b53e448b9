"""The committed study-file reference is the one generated from the models."""

from bayescal.config.reference import study_reference_markdown
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
