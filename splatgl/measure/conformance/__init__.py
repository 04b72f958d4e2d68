"""The conformance kit (``splatgl conformance export|render|score``): self-describing cases any
splat renderer can render, their reference images, and a scorer that says which case fails and
which of the approximations real viewers make best explains each failure (docs/fidelity.md)."""
