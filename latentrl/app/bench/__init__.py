"""``latentrl bench ...``: speed and quality figures, measured side by side, written to JSON.

One module per benchmark (:mod:`.rollout`, :mod:`.env`, :mod:`.train`, :mod:`.motion`), each with
its request dataclass and body; :mod:`.common` holds what they share. Absolute timings on shared
machines are noisy, so every benchmark reports ratios measured in the same run next to absolute
figures labelled with the hardware (:func:`latentrl.timing.hardware`).
"""
