"""File formats and the motion database: BVH, manifests, the database and its cache, input logs,
recordings and network weights. numpy only; never imports the offline (torch) parts."""
