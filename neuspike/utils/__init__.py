"""Shared utilities, one owner each: atomic writes (:mod:`~neuspike.utils.atomic`), JSON records and
hashes (:mod:`~neuspike.utils.jsonio`), named input checks (:mod:`~neuspike.utils.checks`), derived
random generators (:mod:`~neuspike.utils.rng`), compiled backends and thread pinning
(:mod:`~neuspike.utils.parallel`), command-line helpers (:mod:`~neuspike.utils.cli`) and memory, disk
and file-size budgets (:mod:`~neuspike.utils.resources`).

Nothing is imported here, so that a command importing one of them stays cheap.
"""
