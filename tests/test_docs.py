"""The documentation site: references from the code resolve, and the pages agree with the code.

``mkdocs build --strict`` (run by CI) checks the links between pages; these tests check what
mkdocs cannot see: the ``docs/<page>.md#<anchor>`` references in code comments and docstrings;
that the committed CLI reference is the one the typer app generates; that README.md,
docs/index.md and mkdocs.yml list the same pages and the same set-up commands; that the quick
start runs; and that counts written on the pages are the ones the code computes.
"""

from __future__ import annotations

import difflib
import importlib.util
import itertools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REFERENCE = re.compile(r"docs/([A-Za-z0-9_/]+\.md)(#[a-z0-9_-]+)?")
FENCE = re.compile(r"^(```|~~~)")


def heading_anchors(page: Path) -> set[str]:
    """The anchors mkdocs gives the page's headings (Python-Markdown's toc slugs)."""
    toc = pytest.importorskip("markdown.extensions.toc")
    anchors, fenced = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced and line.startswith("#"):
            anchors.add(toc.slugify(line.lstrip("#").strip(), "-"))
    return anchors


def code_references() -> list[tuple[str, str, str | None]]:
    found = []
    for path in sorted([*(ROOT / "src").rglob("*.py"), *(ROOT / "tests").rglob("*.py")]):
        for match in REFERENCE.finditer(path.read_text(encoding="utf-8")):
            found.append((str(path.relative_to(ROOT)), match.group(1), match.group(2)))
    return found


def test_code_refers_to_docs_pages_and_headings_that_exist():
    references = code_references()
    assert len(references) >= 30  # the modules that implement a documented formula cite its page
    broken = []
    for source, page, anchor in references:
        target = DOCS / page
        if not target.is_file():
            broken.append(f"{source}: docs/{page} does not exist")
        elif anchor and anchor[1:] not in heading_anchors(target):
            broken.append(f"{source}: docs/{page} has no heading {anchor}")
    assert broken == []


def test_no_reference_to_a_document_outside_the_repository():
    word = "SP" + "EC"  # spelled apart so this file does not match itself
    hits = [
        f"{path.relative_to(ROOT)}:{number}"
        for path in sorted([*(ROOT / "src").rglob("*.py"), *(ROOT / "tests").rglob("*.py")])
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if word in line
    ]
    assert hits == []


def test_environment_card_has_gymnasium_headings_in_page_and_docstring():
    from solarchain_eval.envs.env import SolarChainEnv

    headings = [
        "Description",
        "Action Space",
        "Observation Space",
        "Rewards",
        "Starting State",
        "Episode End",
        "Arguments",
        "Vectorized environment",
        "Info",
        "Version History",
    ]
    lines = (DOCS / "environment.md").read_text(encoding="utf-8").splitlines()
    page = {line.lstrip("#").strip() for line in lines if line.startswith("## ")}
    assert [h for h in headings if h not in page] == []
    doc = SolarChainEnv.__doc__ or ""
    assert [h for h in headings if f"\n    {h}\n    {'-' * len(h)}\n" not in doc] == []


def _cli_script():
    spec = importlib.util.spec_from_file_location("cli_reference", DOCS / "hooks" / "cli_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_page_is_current():
    """docs/cli.md is committed; regenerate it with ``python docs/hooks/cli_reference.py --write``."""
    committed = (DOCS / "cli.md").read_text(encoding="utf-8")
    generated = _cli_script().cli_page()
    if committed != generated:
        lines = difflib.unified_diff(
            committed.splitlines(keepends=True), generated.splitlines(keepends=True), "docs/cli.md", "generated"
        )
        diff = "".join(itertools.islice(lines, 40))
        pytest.fail(f"docs/cli.md is stale: run python docs/hooks/cli_reference.py --write\n{diff}")


def test_cli_reference_lists_every_command_and_option():
    import typer.main

    from solarchain_eval.cli import app

    markdown = (DOCS / "cli.md").read_text(encoding="utf-8")
    missing = []

    def walk(command, path):
        ctx = command.context_class(command, info_name=path[-1])
        if f"`{' '.join(path)}`" not in markdown:
            missing.append(" ".join(path))
        for param in command.params:
            for name in [*param.opts, *param.secondary_opts]:
                if name.startswith("--") and name not in markdown:
                    missing.append(f"{' '.join(path)} {name}")
        if hasattr(command, "list_commands"):
            for name in command.list_commands(ctx):
                walk(command.get_command(ctx, name), [*path, name])

    walk(typer.main.get_command(app), ["solarchain-eval"])
    assert missing == []
    assert "`solarchain-eval data build`" in markdown and "`--nodes-per-city" in markdown
    # rich's escaped brackets come out as brackets, its tags not at all
    assert "\\[" not in markdown and "[/bold]" not in markdown


# --- one page list, one set of set-up commands ------------------------------------------------

LINK = re.compile(r"\]\(([^)#\s]+\.md)\)")


def _section(text: str, heading: str) -> str:
    """The body of the ``## heading`` section (up to the next ``## `` heading)."""
    match = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"no '## {heading}' section"
    return match.group(1)


def _nav_files(items) -> list[str]:
    files = []
    for item in items:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        files += _nav_files(value) if isinstance(value, list) else [value]
    return files


def readme_pages() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    links = LINK.findall(_section(text, "Documentation"))
    assert all(link.startswith("docs/") for link in links), links
    return [link.removeprefix("docs/") for link in links]


def index_pages() -> list[str]:
    return LINK.findall(_section((DOCS / "index.md").read_text(encoding="utf-8"), "Documentation"))


def nav_pages() -> list[str]:
    yaml = pytest.importorskip("yaml")
    return _nav_files(yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))["nav"])


def test_readme_index_and_nav_list_the_same_pages_in_the_same_order():
    nav = nav_pages()
    assert nav[0] == "index.md" and len(nav) == len(set(nav))
    assert readme_pages() == nav
    assert index_pages() == nav


def _code_blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)\n```$", text, re.S | re.M)


def readme_ci_command(marker: str) -> str:
    """The command CI runs (.ci/run reads the first ```bash block after the marker line)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    match = re.search(rf"^<!-- ci:{marker} -->\n```bash\n(.*?)\n```$", readme, re.S | re.M)
    assert match, f"README.md lacks the ci:{marker} block"
    return match.group(1)


def test_index_shows_the_readme_set_up_commands():
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    blocks = _code_blocks(_section(index, "Set-up in two commands"), "bash")
    assert blocks[:1] == [f"{readme_ci_command('setup')}\n{readme_ci_command('test')}"]
    # the package is not on a registry: every page installs it from a clone (pip install -e '.[extra]')
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
    from_registry = re.compile(r"""pip install ['"]?solarchain-eval""")
    assert [str(p.relative_to(ROOT)) for p in pages if from_registry.search(p.read_text(encoding="utf-8"))] == []


def test_quick_start_is_the_same_on_both_pages_and_runs(capsys):
    readme = _code_blocks(_section((ROOT / "README.md").read_text(encoding="utf-8"), "Quick start"), "python")
    index = _code_blocks(_section((DOCS / "index.md").read_text(encoding="utf-8"), "Quick start"), "python")
    assert len(readme) == 1 and index == readme
    exec(compile(readme[0], "README.md (quick start)", "exec"), {"__name__": "quick_start"})
    violation, liquidity, cost = (float(x) for x in capsys.readouterr().out.split())
    assert 0 <= violation <= 1 and liquidity >= 0 and cost >= 0


# --- pages carry no development log -----------------------------------------------------------

#: Phrases of a lab notebook, not of a product page (case-insensitive).
LOG_PHRASES = (
    "load average",
    "development machine",
    "shared with other jobs",
    "shared 2-core",
    "gpu was lent",
    "this session",
    "helper session",
    "| goal |",
    "| target |",
    "status against",
    "before/after",
    "/tmp/",
    "../shared",
)


def test_pages_carry_no_development_log():
    pages = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
    hits = [
        f"{page.relative_to(ROOT)}:{number}: {phrase}"
        for page in pages
        for number, line in enumerate(page.read_text(encoding="utf-8").lower().splitlines(), 1)
        for phrase in LOG_PHRASES
        if phrase in line
    ]
    assert hits == []


# --- counts written on the pages are computed from the code -----------------------------------


def _flat(text: str) -> str:
    return " ".join(text.split())


def _units(spec) -> tuple[list, list]:
    from solarchain_eval.experiments.grid import plan_units

    units = plan_units(spec)
    return [u for u in units if u.kind == "train"], [u for u in units if u.kind == "eval"]


def test_grid_counts_on_the_pages_are_the_plans():
    from solarchain_eval.data.cities import PAPER_CITIES
    from solarchain_eval.evaluation.settings import KNOWN_SETTINGS
    from solarchain_eval.experiments.grid import GridSpec
    from solarchain_eval.protocol import EPISODE_HOURS, PAPER_EPISODES, PAPER_SEEDS, paper_episode_seeds

    paper = GridSpec.from_preset("paper")
    trains, evals = _units(paper)
    jax_trains, jax_evals = _units(GridSpec.from_preset("paper", backend="jax"))
    assert len(jax_evals) == len(evals)
    t, e, tj = len(trains), len(evals), len(jax_trains)
    episodes = e * PAPER_EPISODES
    agentic = sum(KNOWN_SETTINGS[u.setting].agentic for u in evals) * PAPER_EPISODES * EPISODE_HOURS
    episode_seeds = len({s for seed in PAPER_SEEDS for s in paper_episode_seeds(seed, PAPER_EPISODES)})

    # the stress study's two sweeps (docs/stress.md): the attack sweep's 4 points, the weights' 3
    common = {"timesteps": 20480, "episodes": 20, "seeds": (20260511, 20260512)}
    attack = GridSpec.from_preset(
        "paper",
        settings=("main", "no_physics"),
        policies_by_setting=(
            ("main", ("static", "random", "myopic", "ppo")),
            ("no_physics", ("static", "random", "myopic", "ppo", "ppo-lag")),
        ),
        **common,
    )
    weights = GridSpec.from_preset(
        "paper", settings=("main",), policies=("static", "random", "myopic", "ppo"), **common
    )
    (at, ae), (wt, we) = _units(attack), _units(weights)
    sweep_t, sweep_e = 4 * len(at) + 3 * len(wt), 4 * len(ae) + 3 * len(we)

    expected = {
        "README.md": [f"{t} models, {e} evaluation units in 4 settings"],
        "docs/ray.md": [f"The paper preset is {t + e} units: {t} train units", f"and {e} eval units"],
        "docs/training.md": [
            f"{t} train units (PPO, SAC, DQN",
            f"and {e} eval units",
            f"with `--backend jax`, {tj} train units",
            f"the grid's {t + e} units ({t} train, {e} eval)",
            f"{episodes:,} episode rows, {episodes * EPISODE_HOURS:,} action rows, "
            f"{episodes * EPISODE_HOURS * len(PAPER_CITIES):,} city-hour rows and {agentic:,} agentic log rows",
            f"use only {episode_seeds} distinct episode seeds",
        ],
        "docs/jax.md": [f"The paper preset has {tj} JAX train units instead of {t}", f"{t} models in {tj} seed groups"],
        "docs/stress.md": [f"{sweep_t} models and {sweep_e} evaluation units in all"],
    }
    missing = [
        f"{page}: {phrase!r}"
        for page, phrases in expected.items()
        for phrase in phrases
        if phrase not in _flat((ROOT / page).read_text(encoding="utf-8"))
    ]
    assert missing == []
    # and no page states another count of the paper grid's units
    allowed = {"train": {t, tj, sweep_t}, "eval": {e, sweep_e}, "evaluation": {e, sweep_e}}
    wrong = [
        f"{page.relative_to(ROOT)}: {match.group(0)}"
        for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
        for match in re.finditer(r"\b(\d[\d,]*) (train|eval|evaluation) units", _flat(page.read_text(encoding="utf-8")))
        if int(match.group(1).replace(",", "")) not in allowed[match.group(2)]
    ]
    assert wrong == []
