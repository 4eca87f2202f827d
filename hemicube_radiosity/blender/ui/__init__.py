# SPDX-License-Identifier: GPL-3.0-or-later
"""What an artist sees: properties generated from the schema, the panel, the operators."""
