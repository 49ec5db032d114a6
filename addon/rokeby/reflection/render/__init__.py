"""Final renders of edited reflections (paper §6.2, §6.3, §7.1): ``shading`` (the edited-normal node
groups), ``refraction``, ``rendering`` (keeping materials in sync), ``reflmap`` (reflection maps)."""
