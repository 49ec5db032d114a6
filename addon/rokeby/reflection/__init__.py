"""Reflection editing (Ritschel, Okabe, Thormählen, Seidel 2009, "Interactive Reflection Editing").

``api`` (the entry points: ``__all__``, re-exported by ``rokeby.api``; the sidebar's operators call
them too), ``evaluate`` (scene → arrays → the Rust core → the rotation field), ``props`` (the saved scene
model of mirrors), ``operators``, ``ui``, ``handlers`` (live updates), ``registry`` (what the
mirrors use, tidied after deletions), ``pointers`` (the mirrors and their pointers, below the
evaluator), ``guard`` (suspending the live update), ``duplicates``; ``render/`` (final renders: shader node groups,
refraction, reflection maps) and ``viewport/`` (the live GPU preview).
"""
