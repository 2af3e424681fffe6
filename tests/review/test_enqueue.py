"""The queue takes typed proposals and contexts: a value that does not fit is refused with
its field named and nothing written; a valid one is stored as the text stage 3 built."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from pipeline.review.db import Item, write_session
from pipeline.review.enqueue import enqueue, proposal_hash
from pipeline.review.proposal import InvalidProposal, Proposal, ReviewContext
from pipeline.stage3.inputs import collect, context
from pipeline.stage3.run import proposal_for


def _first(run_dir):
    unit = next(u for u in collect(run_dir) if u.localization is not None)
    return unit, proposal_for(unit, None, None), context(run_dir, unit, 20, 10.0)


@pytest.mark.parametrize(("where", "change", "field"), [
    ("proposal", {"recovery_level": "L7"}, "proposal.recovery_level"),
    ("proposal", {"fail_step": -3}, "proposal.fail_step"),
    ("proposal", {"localizer": {"source": "simstate", "temperature": 0.2}}, "proposal.localizer.temperature"),
    ("context", {"events": [{"step": 3, "time_s": 0.15, "kind": "exploded"}]}, "context.events.0.kind"),
    ("context", {"control_hz": 0}, "context.control_hz"),
])
def test_a_bad_proposal_or_context_is_refused_naming_its_field(run_dir, engine, where, change, field):
    unit, proposal, ctx = _first(run_dir)
    args = {"proposal": proposal, "context": ctx}
    args[where] = {**args[where], **change}
    with write_session(engine) as s:
        with pytest.raises(InvalidProposal) as err:
            enqueue(s, key=unit.key, instruction="x", required_reviews=2, **args)
    assert err.value.field == field and field in str(err.value) and unit.key in str(err.value)
    with write_session(engine) as s:
        assert s.scalar(select(func.count()).select_from(Item)) == 0


def test_a_valid_proposal_is_stored_as_given_and_models_are_taken_too(run_dir, engine):
    unit, proposal, ctx = _first(run_dir)
    with write_session(engine) as s:
        item, _ = enqueue(s, key=unit.key, instruction="x", proposal=proposal, context=ctx, required_reviews=2)
        stored = (item.proposal, item.context, item.proposal_hash)
    assert stored[0] == proposal and list(stored[0]) == list(proposal)  # same keys, same order
    assert stored[1] == ctx and stored[2] == proposal_hash(proposal, False, None)
    with write_session(engine) as s:  # the typed forms are the same proposal: nothing new
        _, created = enqueue(s, key=unit.key, instruction="x", proposal=Proposal.model_validate(proposal),
                             context=ReviewContext.model_validate(ctx), required_reviews=2)
    assert not created
