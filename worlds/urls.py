"""The worlds' pages, under /worlds/ (included by robotide.urls).

The editor's pages (/worlds/new, /worlds/<id>/edit: worlds.editor_views) are added below by
the editor's author.
"""

from django.urls import path

from worlds import editor_views, views

urlpatterns = [
    path("", views.world_list, name="world-list"),
    path("import", views.world_import, name="world-import"),
    path("<int:world_id>.json", views.world_export, name="world-export"),
    path("builtin/<slug:name>.json", views.builtin_export, name="world-builtin-export"),
    path("<int:world_id>/shares/", views.world_shares, name="world-shares"),
    path(
        "<int:world_id>/shares/<int:share_id>/delete",
        views.world_unshare,
        name="world-unshare",
    ),
    path("<int:world_id>/delete", views.world_delete, name="world-delete"),
    # The editor's (worlds.editor_views):
    path("new", editor_views.world_new, name="world-new"),
    path("<int:world_id>/edit", editor_views.world_edit, name="world-edit"),
    path("builtin/<slug:name>", editor_views.world_builtin, name="world-builtin"),
]
