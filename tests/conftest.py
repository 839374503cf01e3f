"""Session-wide test settings."""

import os

# Ray reads this once, when it is first imported (ray_private.ray_constants), and torchrl imports
# Ray as soon as any test module imports the collectors. Unset, Ray advertises the machine's network
# address for a cluster started on 127.0.0.1 and the driver never reaches it (the hang the Ray tests
# used to show). The tests only ever start Ray on loopback, so keep it there for the whole session.
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
