"""The characterizer reads what stage 2 wrote: reuse stage 2's session fixtures."""

from tests.stage2.conftest import episodes, spatial_env, stage1_run, stage2_run  # noqa: F401
