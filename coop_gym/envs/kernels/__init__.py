"""The compiled step every env runs.

The packed rows (:mod:`.layout`), the step (:mod:`.step`) and its threaded form (:mod:`.threads`,
sharing work through :mod:`.atomics`), the reset (:mod:`.reset`) and the generators of a batch
seeded in one call (:mod:`.seeding`), the report row and the episode end (:mod:`.report`).
"""
