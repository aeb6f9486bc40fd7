"""Pictures of graphs (``flowtact graph``) and of recordings (``flowtact plot``); matplotlib is the
``plot`` extra, imported only here and only when a picture is made."""
