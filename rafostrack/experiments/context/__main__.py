"""`python -m rafostrack.experiments.context`: the context paper's experiments and REPORT.md."""

from rafostrack.experiments.runner import paper_main

if __name__ == "__main__":
    paper_main("context")
