"""Simulated missions and scores against their truth: the tracker's own model
(`simulate`, `scenarios`), the stress generator that is not the tracker's model
(`stress`), mission directories on disk (`mission_writer`) and scores (`evaluate`).
Built on the core; the core never imports it."""
