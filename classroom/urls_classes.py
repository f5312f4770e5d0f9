"""Routes of the classroom's pages."""

urlpatterns: list = []
