"""Reflection editing (Ritschel, Okabe, Thormählen, Seidel 2009, "Interactive Reflection Editing").

``evaluate`` (scene → arrays → the Rust core → the rotation field), ``props`` (the saved scene
model of mirrors), ``operators``, ``ui``, ``handlers`` (live updates), ``registry`` (what the
add-on owns in the open file), ``duplicates``; ``render/`` (final renders: shader node groups,
refraction, reflection maps) and ``viewport/`` (the live GPU preview).
"""
