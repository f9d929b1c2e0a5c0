"""The count of a writer's matched readers survives cyclonedds-python's race (``moose_ros.runtime.dds``): its
``get_matched_subscriptions`` raises IndexError when a reader matches between its two calls to Cyclone DDS, which
killed a node of the fault matrix at start-up (CI, 4d2ee81)."""
from __future__ import annotations

from typing import Any

from moose_ros.runtime.dds import MATCH_RETRIES, matched_subscriptions


class RacingWriter:
    """Answers like cyclonedds-python's DataWriter: ``races`` times the IndexError of a reader matching meanwhile,
    then the readers matched by then."""

    def __init__(self, races: int, readers: int) -> None:
        self.races, self.readers, self.calls = races, readers, 0

    def get_matched_subscriptions(self) -> list[Any]:
        self.calls += 1
        if self.calls <= self.races:
            raise IndexError("invalid index")
        return list(range(self.readers))


def test_a_reader_matching_during_the_count_is_counted_not_fatal() -> None:
    writer = RacingWriter(races=2, readers=3)
    assert matched_subscriptions(writer) == 3 and writer.calls == 3


def test_a_count_that_never_settles_is_an_error_not_a_guess() -> None:
    writer = RacingWriter(races=MATCH_RETRIES, readers=3)
    try:
        matched_subscriptions(writer)
    except IndexError:
        assert writer.calls == MATCH_RETRIES
    else:
        raise AssertionError("an unsettled count was returned")
