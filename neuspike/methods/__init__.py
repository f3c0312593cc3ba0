"""The method machinery: the common interface and its registry (:mod:`~neuspike.methods.registry`,
re-exported here: ``from neuspike.methods import Method, create``), the base of learned methods
(:mod:`~neuspike.methods.learned`), their weights (:mod:`~neuspike.methods.weights`), the input
representations (:mod:`~neuspike.methods.representations`) and the normalisation of outputs
(:mod:`~neuspike.methods.normalisation`).

Only the registry is imported here (it needs neither torch nor the methods themselves).
"""

from neuspike.methods.registry import (
    ENTRY_POINT_GROUP,
    Created,
    Method,
    MethodEntry,
    MethodUnavailable,
    WeightsConfig,
    available,
    check_device,
    create,
    create_many,
    entry,
    load_entry_points,
    register,
    unregister,
    uses_device,
)

__all__ = [
    "ENTRY_POINT_GROUP", "Created", "Method", "MethodEntry", "MethodUnavailable", "WeightsConfig", "available",
    "check_device", "create", "create_many", "entry", "load_entry_points", "register", "unregister", "uses_device",
]
