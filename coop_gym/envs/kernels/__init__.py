"""The compiled step every env runs.

The packed rows (:mod:`.layout`), the step (:mod:`.step`) and its threaded form (:mod:`.threads`),
the reset (:mod:`.reset`), the report row and the episode end (:mod:`.report`).
"""
