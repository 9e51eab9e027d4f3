"""One set of rules: every scenario file of the project gets the same verdict from `validate` and
from the planner. A file validate accepts is scheduled without a word (the planner finds nothing
validate missed); a file it refuses does not load (the reader raises the same problems)."""

from pathlib import Path

import pytest

import master.api as api
from master.scenario import ScenarioError

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted(p for d in ("tests", "models", "docs") for p in (ROOT / d).rglob("*.ss[dp]"))


def test_the_project_has_scenarios_of_every_kind():
    assert len([p for p in SCENES if "/bad/" in str(p)]) >= 12 and len(SCENES) >= 20


@pytest.mark.parametrize("path", SCENES, ids=[str(p.relative_to(ROOT)) for p in SCENES])
def test_validate_and_the_planner_give_the_same_verdict(path):
    problems = api.validate(path)
    if problems:
        with pytest.raises(ScenarioError) as refused:
            api.load_scenario(path)
        assert [str(p) for p in refused.value.problems] == [str(p) for p in problems]
    else:
        plan = api.plan(api.load_scenario(path))  # raises PlanError where the rules differ
        assert plan.n_macro > 0
