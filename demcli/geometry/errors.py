"""The one exception of the geometry toolkit."""


class GeometryError(ValueError):
    """Input that does not describe the solid or polygon asked for.

    Raised for degenerate point sets (fewer than 4 distinct points, coplanar or
    collinear points, NaN or inf coordinates) with a message that says which; Qhull's
    own error text is never shown as a traceback.
    """
