"""The simstate labelers: rules over the simulator evidence, no model. `events` (what
happened, per rule), `localizer` (the onset among the events), `characterizer` (level,
category, action), `labeler` (both behind the protocols of `pipeline.labelers.base`)."""
