"""An analysis that fails: the others must still run and the error must reach the user."""

REPORT = "broken.pdf"
ORDER = 3


def build(out, model):
    raise ValueError("an analysis failed on purpose")
