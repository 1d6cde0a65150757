"""Sample content shipped with glradial (see README.md beside this file for sources and licences)."""
