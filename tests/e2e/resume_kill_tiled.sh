#!/bin/sh
# resume_kill_tiled.sh: resume_kill.sh on a tiled output (--tasks stamps:64x48 -> a tiled
# OpenEXR file of 64x48 tiles, partial at the right and bottom edges): SIGKILL at the same
# instants, --resume keeps every whole tile row on disk, and the final file is byte-identical
# to an uninterrupted render.
RESUME_TASKS=stamps:64x48 exec sh "$(dirname "$0")/resume_kill.sh"
