"""Render-farm jobs (Open Job Description, ``jobtemplate-2023-09``): job bundles that ``openjd run``
runs on one machine and Deadline Cloud runs at scale, with the extension zip travelling in the job.

Entry points (``rokeby.farm.api``, re-exported by ``rokeby.api``): ``write_render_job``. Command line:
``python -m rokeby.farm render FILE.blend BUNDLE_DIR [--frames A-B] [--chunk N]``. Guide:
docs/farm.md; tests: tests/workflows/test_farm_jobs.py.
"""

from .api import write_render_job

__all__ = ["write_render_job"]
