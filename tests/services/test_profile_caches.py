"""What is derived from a profile (its catalogue, its drive-control family) is kept for a bounded number of profiles:
a server that sees many profiles (uploads replaced again and again, a vendor's folder browsed) does not keep every
profile it ever derived something from (issue 29, one catalogue cache)."""

from __future__ import annotations

import gc
import weakref

from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.bus.sessions import SessionNode
from drivebench.services.control.drive_words import family_of_profile
from drivebench.services.sets.parameter_sets import catalog_for

KEPT_AT_MOST = 64


def test_the_derived_data_of_many_profiles_does_not_keep_them_all() -> None:
    servo = ProfileRegistry().get("generic-cia402-servo")
    alive = []
    for _round in range(3 * KEPT_AT_MOST):
        profile = servo.model_copy()  # what an upload replacing the profile brings: a new object, the same id
        assert family_of_profile(profile) is not None
        assert catalog_for(profile).profile is profile
        assert SessionNode(node_id=1, profile=profile).catalog is not None
        alive.append(weakref.ref(profile))
        del profile
    gc.collect()
    assert sum(ref() is not None for ref in alive) <= KEPT_AT_MOST


def test_one_profile_object_gets_one_catalogue_and_a_new_object_a_new_one() -> None:
    servo = ProfileRegistry().get("generic-cia402-servo")
    assert catalog_for(servo) is catalog_for(servo)
    replaced = servo.model_copy()
    assert catalog_for(replaced) is not catalog_for(servo)
    assert catalog_for(replaced).profile is replaced
    assert family_of_profile(replaced) is not family_of_profile(servo)
    assert SessionNode(node_id=1, profile=replaced).catalog is catalog_for(replaced)  # one cache, not one per node
