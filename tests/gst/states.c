/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* The generic state-change test: every element of the lftag plugin, on its own and
 * with its properties at their defaults, goes through every state change and back,
 * directly and step by step, without failing, leaking or crashing. */
#include "check-main.h"

static const GstState sequences[][8] = {
    {GST_STATE_READY, GST_STATE_PAUSED, GST_STATE_PLAYING, GST_STATE_PAUSED, GST_STATE_READY, GST_STATE_NULL},
    {GST_STATE_PLAYING, GST_STATE_NULL},
    {GST_STATE_PAUSED, GST_STATE_NULL},
    {GST_STATE_READY, GST_STATE_PLAYING, GST_STATE_READY, GST_STATE_PAUSED, GST_STATE_PLAYING, GST_STATE_NULL},
};

static GList* plugin_element_factories(void) {
  GList* features = gst_registry_get_feature_list_by_plugin(gst_registry_get(), "lftag");
  GList* factories = NULL;

  for (GList* l = features; l != NULL; l = l->next)
    if (GST_IS_ELEMENT_FACTORY(l->data)) factories = g_list_prepend(factories, gst_object_ref(l->data));
  gst_plugin_feature_list_free(features);
  return factories;
}

static void run_sequences(GstElement* element, const gchar* name) {
  for (guint i = 0; i < G_N_ELEMENTS(sequences); ++i) {
    for (guint k = 0; k < G_N_ELEMENTS(sequences[i]); ++k) {
      GstState state = sequences[i][k];
      GstStateChangeReturn ret = gst_element_set_state(element, state);
      fail_if(ret == GST_STATE_CHANGE_FAILURE, "%s: change to %s failed", name, gst_element_state_get_name(state));
      ret = gst_element_get_state(element, NULL, NULL, 10 * GST_SECOND);
      fail_if(ret == GST_STATE_CHANGE_FAILURE || ret == GST_STATE_CHANGE_ASYNC, "%s: change to %s did not complete",
              name, gst_element_state_get_name(state));
      if (state == GST_STATE_NULL) break;
    }
  }
}

GST_START_TEST(test_state_changes_alone) {
  GList* factories = plugin_element_factories();

  fail_unless(factories != NULL, "the lftag plugin provides no elements: not loaded?");
  for (GList* l = factories; l != NULL; l = l->next) {
    const gchar* name = gst_plugin_feature_get_name(l->data);
    GstElement* element = gst_element_factory_create(l->data, NULL);
    fail_unless(element != NULL, "cannot create %s", name);
    run_sequences(element, name);
    gst_object_unref(element);
  }
  gst_plugin_feature_list_free(factories);
}
GST_END_TEST;

/* Sources in a pipeline stream while they change state, live and not. */
GST_START_TEST(test_state_changes_in_pipeline) {
  GList* factories = plugin_element_factories();
  guint sources = 0;

  for (GList* l = factories; l != NULL; l = l->next) {
    const gchar* name = gst_plugin_feature_get_name(l->data);
    if (!gst_element_factory_list_is_type(l->data, GST_ELEMENT_FACTORY_TYPE_SRC)) continue;
    for (gint live = 0; live < 2; ++live) {
      gchar* launch = g_strdup_printf("%s is-live=%d ! fakesink sync=true", name, live);
      GstElement* pipeline = gst_parse_launch(launch, NULL);
      fail_unless(pipeline != NULL, "cannot build %s", launch);
      run_sequences(pipeline, launch);
      gst_object_unref(pipeline);
      g_free(launch);
    }
    ++sources;
  }
  fail_unless(sources > 0, "the lftag plugin has no source element");
  gst_plugin_feature_list_free(factories);
}
GST_END_TEST;

static Suite* states_suite(void) {
  Suite* s = suite_create("states");
  TCase* tc = tcase_create("general");

  suite_add_tcase(s, tc);
  tcase_add_test(tc, test_state_changes_alone);
  tcase_add_test(tc, test_state_changes_in_pipeline);
  return s;
}

LFTAG_CHECK_MAIN(states)
