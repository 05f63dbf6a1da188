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


def _hook(name: str):
    spec = importlib.util.spec_from_file_location(name, DOCS / "hooks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_index_is_generated_from_the_readme():
    """docs/index.md is README.md with site links; regenerate it with ``python docs/hooks/index_page.py --write``."""
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    assert index == _hook("index_page").index_page(), (
        "docs/index.md is stale: run python docs/hooks/index_page.py --write"
    )
    # the CI commands are on both pages, and the links that leave docs/ are named, not linked
    assert (
        f"```bash\n{readme_ci_command('setup')}\n```" in index and f"```bash\n{readme_ci_command('test')}\n```" in index
    )
    assert "](docs/" not in index and "](LICENSE)" not in index


def test_index_generator_rewrites_links():
    # "docs/" and the page name apart, so the reference scan above does not read this as a link
    readme = "# T\n[a](" + "docs" + "/x.md#h) [`CITATION.cff`](CITATION.cff) [LICENSE](LICENSE) [w](https://e.org)\n"
    page = _hook("index_page").index_page(readme)
    assert page.splitlines()[-1] == "[a](x.md#h) `CITATION.cff` `LICENSE` [w](https://e.org)"


def test_pages_install_from_a_clone_and_use_data_folders_that_exist():
    # the package is not on a registry: every page installs it from a clone (pip install -e '.[extra]')
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
    from_registry = re.compile(r"""pip install ['"]?solarchain-eval""")
    assert [str(p.relative_to(ROOT)) for p in pages if from_registry.search(p.read_text(encoding="utf-8"))] == []
    # --data names a folder a command of the docs makes (data/paper) or a placeholder in capitals
    datas = {
        f"{p.relative_to(ROOT)}: {m.group(1)}"
        for p in pages
        for m in re.finditer(r"--data\s+([^\s`;,)]+)", p.read_text(encoding="utf-8"))
        if m.group(1) not in ("data/paper", "DIR", "DATA", "PATH") and not m.group(1).startswith(("$", "str("))
    }
    assert datas == set()


def test_first_screen_says_what_is_exact_and_what_is_not():
    first = (ROOT / "README.md").read_text(encoding="utf-8").split("## ", 1)[0]
    assert "exactly." not in first  # the old claim: "reproduces the published results ... exactly."
    for phrase in ("**Exactly**", "**Up to training noise**", "**Only with the paper's hosted model**"):
        assert phrase in first, phrase
    assert "docs/deviations.md" in first and "LICENSE" in first


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
    # the supply-chain market's grid (docs/tasks/supply_chain_findings.md, docs/performance.md): its own baseline too
    supply_trains, supply_evals = _units(GridSpec.from_preset("paper", backend="jax", task="supply-chain"))
    assert len(supply_evals) == e + len(PAPER_SEEDS) * 2  # base-stock in main and no_physics, per seed
    # and no page states another count of the paper grid's units
    allowed = {
        "train": {t, tj, sweep_t, len(supply_trains)},
        "eval": {e, sweep_e, len(supply_evals)},
        "evaluation": {e, sweep_e, len(supply_evals)},
    }
    wrong = [
        f"{page.relative_to(ROOT)}: {match.group(0)}"
        for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
        for match in re.finditer(r"\b(\d[\d,]*) (train|eval|evaluation) units", _flat(page.read_text(encoding="utf-8")))
        if int(match.group(1).replace(",", "")) not in allowed[match.group(2)]
    ]
    assert wrong == []


# --- the CLI page keeps what --help prints ----------------------------------------------------


def _help_entries(output: str) -> list[str]:
    """Each option's description as ``--help`` prints it (click's layout: names, two spaces, text)."""
    entries: list[str] = []
    inside = False
    for line in output.splitlines():
        if line.rstrip().endswith(":") and not line.startswith(" "):
            inside = line.startswith("Options")
            continue
        if not inside or not line.strip():
            continue
        if re.match(r"^  -", line):
            parts = re.split(r"\s{2,}", line.strip(), maxsplit=1)
            entries.append(parts[1] if len(parts) == 2 else "")
        elif entries:
            entries[-1] += " " + line.strip()
    return [e for e in entries if e]


def test_cli_page_shows_every_option_help_as_help_prints_it():
    """Checked against ``--help`` itself, not the page's generator: brackets such as ``'.[ray]'`` and
    ``[default: ...]`` must survive."""
    import typer.main
    from typer.testing import CliRunner

    from solarchain_eval.cli import app

    page = (DOCS / "cli.md").read_text(encoding="utf-8").replace("\\|", "|").replace("&lt;", "<")
    squeezed = re.sub(r"\s+", "", page)
    runner, missing, checked = CliRunner(), [], 0

    def walk(command, path):
        nonlocal checked
        result = runner.invoke(app, [*path, "--help"], terminal_width=100)
        assert result.exit_code == 0, result.output
        for entry in _help_entries(result.output):
            checked += 1
            if re.sub(r"\s+", "", entry) not in squeezed:
                missing.append(f"{' '.join(['solarchain-eval', *path])}: {entry[:80]}")
        ctx = command.context_class(command, info_name=path[-1] if path else "solarchain-eval")
        if hasattr(command, "list_commands"):
            for name in command.list_commands(ctx):
                walk(command.get_command(ctx, name), [*path, name])

    walk(typer.main.get_command(app), [])
    assert checked > 200 and missing == []
    assert "pip install -e '.[ray]'" in page


# --- generated facts on the pages -------------------------------------------------------------


def test_observation_ranges_on_the_environment_card_are_measured(published_dir):
    page = (DOCS / "environment.md").read_text(encoding="utf-8")
    committed = re.search(r"<!-- observation-ranges:start -->\n(.*?)<!-- observation-ranges:end -->", page, re.S)
    assert committed, "docs/environment.md lacks the observation-ranges block"
    measured = _hook("observation_ranges").ranges_table(published_dir)
    assert committed.group(1) == measured, f"run python docs/hooks/observation_ranges.py:\n{measured}"
    # the facts the examples are tuned by: the gap never negative, ν's median 0.08
    rows = {line.split("|")[2].strip(" `"): line.split("|")[3:8] for line in measured.splitlines()[2:]}
    assert float(rows["supply_gap"][0]) == 0 and float(rows["raw_physics_record_rate"][2]) == 0.08


# --- the Public API page ------------------------------------------------------------------------


def test_public_api_page_names_importable_objects_and_the_real_signature():
    import importlib
    import inspect

    import solarchain_eval

    page = (DOCS / "public_api.md").read_text(encoding="utf-8")
    paths = re.findall(r"^\| `[^`]+` \| `(solarchain_eval\.[A-Za-z_.]+)` \|", page, re.M)
    assert len(paths) >= 10
    for path in paths:
        module, _, attr = path.rpartition(".")
        assert hasattr(importlib.import_module(module), attr), path
    block = _code_blocks(_section(page, "`evaluate`"), "python")[0]
    documented = re.findall(r"^    (\w+)=", block, re.M)
    actual = [n for n, p in inspect.signature(solarchain_eval.evaluate).parameters.items() if p.kind == p.KEYWORD_ONLY]
    assert documented == actual


# --- one figure per fact ------------------------------------------------------------------------

#: Measured times of the paper preset and of SAC's training; each lives in docs/performance.md only.
MEASURED_TIMES = re.compile(r"\b\d+(?:\.\d+)? ?(?:min|minutes|h)\b(?! ?/)")


def test_run_times_are_stated_once_in_the_performance_notes():
    """Other pages link to the performance notes instead of repeating (and drifting from) a time."""
    pages = ["README.md", "docs/paper_map.md", "docs/jax.md", "docs/training.md", "docs/ray.md", "docs/index.md"]
    stated = {page: MEASURED_TIMES.findall(_flat((ROOT / page).read_text(encoding="utf-8"))) for page in pages}
    assert {page: found for page, found in stated.items() if found} == {}
    performance = _flat((DOCS / "performance.md").read_text(encoding="utf-8"))
    for figure in ("**2.66 h**", "2,699 s = 45.0 min", "46.2 min"):
        assert performance.count(figure) == 1, figure


def test_counts_on_the_performance_and_environment_pages_follow_the_protocol():
    from solarchain_eval.market.baselines import BASELINES
    from solarchain_eval.protocol import EPISODE_HOURS, PAPER_EPISODES, PAPER_SEEDS

    steps = len(PAPER_SEEDS) * PAPER_EPISODES * EPISODE_HOURS
    performance = _flat((DOCS / "performance.md").read_text(encoding="utf-8"))
    environment = _flat((DOCS / "environment.md").read_text(encoding="utf-8"))
    assert f"({len(PAPER_SEEDS)} run seeds × {PAPER_EPISODES} episodes = {steps:,} steps" in performance
    bench_episodes = len(BASELINES) * 2 * 9 * PAPER_EPISODES  # perf/env_bench.py: 2 settings × 9 run seeds
    assert f"{bench_episodes:,} baseline episodes" in performance
    observed = len(BASELINES) * steps
    assert (
        f"({len(PAPER_SEEDS)} run seeds × {PAPER_EPISODES} episodes × {EPISODE_HOURS} steps each, {observed:,} observations)"
        in environment
    )


def test_api_pages_list_their_modules_readably():
    """Each docs/api page opens with its modules and their summaries (``python docs/hooks/api_pages.py --write``)."""
    hook = _hook("api_pages")
    stale = []
    for page in sorted((DOCS / "api").glob("*.md")):
        text = page.read_text(encoding="utf-8")
        if hook.refreshed(text) != text:
            stale.append(page.name)
        documented = re.findall(r"^::: ([\w.]+)", text, re.M)
        assert all(f"| `{module}` |" in text for module in documented), page.name
    assert stale == []
