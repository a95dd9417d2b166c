"""The papers' experiments, redone with rafostrack (`make figures`).

One subpackage per paper (`ranked`: the ranked-signal tracking paper), one module per
figure or table; `common` holds what they share and `runner` runs them and builds the
reports (`python -m papers`).
"""
