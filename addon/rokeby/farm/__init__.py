"""Render-farm jobs (Open Job Description, ``jobtemplate-2023-09``): job bundles that ``openjd run``
runs on one machine and Deadline Cloud runs at scale, with the extension zip travelling in the job.

Entry points (``rokeby.farm.api``, re-exported by ``rokeby.api``): ``write_render_job`` (a saved
.blend's frames) and ``write_recomposite_job`` (a folder of multilayer EXRs through
``python -m rokeby.composite``). Command line: ``python -m rokeby.farm render|recomposite …``.
``marker`` records in saved files which Rokeby saved them; ``worker`` is what the jobs run inside
the worker's Blender; ``ui.py`` is the *Export Farm Job…* operator, ``addon.py`` registers it,
``__main__.py`` is the command line. Guide: docs/farm.md; tests: tests/workflows/test_farm_jobs.py.
"""

from .api import write_recomposite_job, write_render_job

__all__ = ["write_render_job", "write_recomposite_job"]
