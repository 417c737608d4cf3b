"""The guided test session (``tankdaq session``): the campaign plan drives the recording, condition by
condition, with the operator.

Rooms: ``plan`` (the test matrix as the session walks it), ``journal`` (``session.jsonl`` and the lock),
``checks`` (pure acceptance checks of a decay), ``measure`` (what the checks look at, read from a
recording or the still water), ``watch`` (the model between decays: drift, a bump, level), ``state``
(where the session stands, from its log alone), ``recovery`` (what the folder holds that the log does
not say), ``panel`` (the campaign panel), ``operator``
(the questions and who answers them), ``report`` (the report of the accepted decays) and ``runner``
(``GuidedSession``: the loop). Each is imported from its own module.
"""
