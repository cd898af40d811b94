"""The README's results summary and docs/results.md are generated from metrics/: the committed pages agree
with the committed metrics, a page with one number changed is caught, and the README is for users: no
dates and no issue numbers."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from offroad_path.report.readme import BEGIN, END, generated, main, with_results

ROOT = Path(__file__).resolve().parents[2]


def pages(readme: Path = ROOT / "README.md", results: Path = ROOT / "docs" / "results.md") -> list[str]:
    return ["--readme", str(readme), "--results", str(results), "--metrics", str(ROOT / "metrics")]


def test_the_readme_results_are_the_committed_metrics():
    assert main(["--check", *pages()]) == 0
    for page in (ROOT / "docs").glob("results-*.md"):  # a scaled pipeline's committed run (docs/results-gpu.md), where there is one
        pipeline = page.stem.removeprefix("results-")
        assert main(["--check", "--pipeline", pipeline, "--results", str(page), "--metrics", str(ROOT / pipeline / "metrics")]) == 0
    summary, full = generated(ROOT / "metrics"), generated(ROOT / "metrics", full=True)
    assert summary in (ROOT / "README.md").read_text() and full in (ROOT / "docs" / "results.md").read_text()
    assert "Primary questions" in summary and "Exploratory comparisons" not in summary and "Exploratory comparisons" in full


def test_the_readme_holds_no_date_and_no_issue_number():
    readme = (ROOT / "README.md").read_text()
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", readme), "a date in the README: history goes to CHANGELOG.md"
    assert not re.search(r"(?i)\bissue \d+|#\d{2,}\b", readme), "an issue number in the README"
    assert not re.search(r"(?i)\b(xeon|epyc|avx-?512|avx2)\b", readme), "a CPU in the README: provenance goes to docs/results.md"
    assert len(readme.splitlines()) <= 250


def test_a_readme_with_one_number_changed_fails_the_check(tmp_path, capsys):
    readme = (ROOT / "README.md").read_text()
    block = readme.split(BEGIN)[1].split(END)[0]
    number = re.search(r"\| (\d\.\d{3}) \[", block)  # the first IoU of the results table
    assert number is not None
    changed = f"{float(number.group(1)) + 0.001:.3f}"
    edited = readme.replace(block, block.replace(number.group(0), f"| {changed} [", 1))
    assert edited != readme
    (tmp_path / "README.md").write_text(edited)
    (tmp_path / "results.md").write_text((ROOT / "docs" / "results.md").read_text())
    assert main(["--check", *pages(tmp_path / "README.md", tmp_path / "results.md")]) == 1
    assert "README.md: its results disagree with" in capsys.readouterr().err
    assert main(pages(tmp_path / "README.md", tmp_path / "results.md")) == 0  # regenerated
    assert (tmp_path / "README.md").read_text() == readme


def test_a_scaled_pipelines_page_is_made_beside_the_laptops_with_its_stage_times(tmp_path, capsys):
    """--pipeline tour: docs/results-tour.md from tour/metrics, under experiment=tour's settings, as
    --pipeline gpu makes docs/results-gpu.md (here the committed metrics, whose primaries are the tour's,
    with a stage-time file as tools/parallel_repro.py writes one); the README untouched."""
    import json
    import shutil

    metrics = tmp_path / "metrics"
    shutil.copytree(ROOT / "metrics", metrics)
    timing = {"machine": "a test host", "total_s": 125.0, "jobs": 4, "complete": False, "unfinished": ["drive"],
              "stages": {"synthesize": 60.0, "label": 20.5}, "spans": {"synthesize": [0.0, 60.0], "label": [60.0, 80.5]}}  # fmt: skip
    (metrics / "pipeline_time.json").write_text(json.dumps(timing))
    page, readme = tmp_path / "results-tour.md", (ROOT / "README.md").read_text()
    arguments = ["--pipeline", "tour", "--metrics", str(metrics), "--results", str(page), "--readme", str(tmp_path / "README.md")]
    assert main(arguments) == 0 and not (tmp_path / "README.md").exists()
    text = page.read_text()
    assert text.startswith("# Results of the `experiment=tour` run\n") and BEGIN in text and END in text
    assert "The `experiment=tour` run: `dvc repro tour/dvc.yaml` (`tour/dvc.lock`, `tour/metrics/`" in text
    assert "stopped before drive finished, 2 min 5 s on a test host, up to 4 stages at once" in text
    assert "| synthesize | 0 | 60.0 |\n| label | 60 | 20.5 |" in text
    assert generated(metrics, full=True, pipeline="tour") in text
    assert main(["--check", *arguments]) == 0
    timing["spans"]["label"] = [60.0, 81.5]
    (metrics / "pipeline_time.json").write_text(json.dumps(timing))
    assert main(["--check", *arguments]) == 1 and "results-tour.md: its results disagree with" in capsys.readouterr().err
    assert (ROOT / "README.md").read_text() == readme


def test_the_block_needs_both_markers():
    with pytest.raises(ValueError, match=r"README\.md: needs one"):
        with_results("# no markers\n", "text")
    assert with_results(f"a\n{BEGIN}\nold\n{END}\nb\n", "new\n") == f"a\n{BEGIN}\n\nnew\n\n{END}\nb\n"
    assert "| SegNet | none | no |" in generated(ROOT / "metrics")


def test_pilotnet_seeds_are_summarised_and_a_collapsed_one_is_named():
    from offroad_path.report.summary import _steering, pilotnet_check

    row = {"mae": 0.1}
    evaluation = {"steering_from_paths": {"straight_ahead": {"mae": 0.21}, "pilotnet": row, "label_ceiling": {"mae": 0.07}}}
    seeds = [{"seed": s, "mean_absolute_error": e, "straight_ahead_mean_absolute_error": 0.213, "test_frames": 10,
              "largest_predicted_magnitude": m, "largest_true_magnitude": 0.47, "straight_ahead_margin": 0.213 - e,
              "straight_ahead_margin_interval": [0.213 - e - 0.02, 0.213 - e + 0.02], "beats_straight_ahead": 0.213 - e > 0.02,
              "prediction_spread_ratio": r, "correlation_with_truth": c, "collapsed": r < 0.25}
             for s, e, m, r, c in ((0, 0.094, 0.45, 0.8, 0.7), (1, 0.097, 0.40, 0.6, 0.6), (2, 0.213, 0.01, 0.01, 0.05))]  # fmt: skip
    text = _steering(evaluation, seeds)[0]
    assert "over its 3 training seeds 0.135 ± 0.068, mean ± sd" in text  # mean 0.1347, sd 0.0679 by hand
    check = pilotnet_check(seeds)
    assert "seed 2 0.213 (straight ahead 0.213; margin +0.000 [-0.020, +0.020]; spread 0.01 of the truth's, correlation 0.05)" in check
    assert "Seed 2 collapsed (1 of 3" in check and "seed 2 does not steer closer to the true angle than straight ahead" in check
    assert "No seed collapsed; every seed steers closer" in pilotnet_check(seeds[:2]) and "collapsed (" not in pilotnet_check(seeds[:2])
    # one of the drive's PilotNets: named, with the same check
    slip = pilotnet_check(seeds[2:], "PilotNet trained on slip")
    assert slip.startswith("PilotNet trained on slip, the same check: seed 2 0.213") and "Seed 2 collapsed (1 of 1" in slip


HISTORY_PAGES: set[str] = set()  # history lives in CHANGELOG.md alone


def test_the_readme_the_docs_and_the_benchmarks_name_no_commit():
    """A "before" is rebuilt from a tag or the CHANGELOG's entry: no commit hash in the README, docs/ or
    benchmarks/ (history lives in CHANGELOG.md)."""
    commit = re.compile(r"(?<![\w./-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![\w-])")
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "benchmarks").glob("*.*"))]
    found = [
        f"{path.relative_to(ROOT)}: {hit}" for path in pages if path.suffix in (".md", ".py") for hit in commit.findall(path.read_text())
    ]
    assert not found, found


def test_the_benchmarks_page_is_one_short_section_per_benchmark():
    """benchmarks/README.md: what each benchmark measures, its command, its latest figure; the
    narratives of earlier rounds live in CHANGELOG.md. Every script is named in it."""
    page = (ROOT / "benchmarks" / "README.md").read_text()
    assert len(page.splitlines()) <= 500
    helpers = {"common.py", "raw_rig.py"}  # what the benchmarks share, no benchmark of their own
    unnamed = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py") if p.name not in helpers and p.name not in page)
    assert not unnamed, f"benchmarks/README.md names no section for {unnamed}"


def test_the_product_holds_no_issue_number_and_the_docs_no_date():
    """Code, configuration, docs and benchmarks say what is, not when or in which issue it came:
    no issue numbers anywhere in them, no dates in src/, conf/, docs/ and benchmarks/README.md
    (history pages excepted)."""
    issue, date = re.compile(r"(?i)\bissue \d+|\bissues? #?\d{2,}\b"), re.compile(r"\b20\d\d-\d\d-\d\d\b")
    found = []
    for folder, suffixes in (("src", (".py",)), ("conf", (".yaml",)), ("docs", (".md",)), ("benchmarks", (".py", ".md"))):
        for path in sorted((ROOT / folder).rglob("*")):
            name = str(path.relative_to(ROOT))
            if path.suffix not in suffixes or name in HISTORY_PAGES:
                continue
            text = path.read_text()
            found += [f"{name}: an issue number" for _ in issue.findall(text)[:1]]
            if folder != "benchmarks" or path.suffix == ".md":
                found += [f"{name}: a date" for _ in date.findall(text)[:1]]
    assert not found, found
