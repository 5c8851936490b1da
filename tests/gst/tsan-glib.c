/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* For the ThreadSanitizer build only: GLib's GMutex, GRecMutex and GCond are futexes
 * and atomics inside an uninstrumented libglib, so ThreadSanitizer sees none of the
 * ordering they give, and would report every access made under GST_OBJECT_LOCK, or handed
 * from one thread to another through a GstQueue, as a race. Linked into a test program,
 * these wrappers take the place of GLib's functions (for GStreamer, the plugin and GLib
 * itself, which call them through the PLT), call the real ones and tell ThreadSanitizer
 * what happened. Nothing else changes. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <glib.h>
#include <sanitizer/tsan_interface.h>

/* The real function, looked up once (atomically: the first calls may come at once). */
#define REAL(name)                                                                     \
  static __typeof__(&name) real_##name##_p;                                            \
  __typeof__(&name) real_##name = __atomic_load_n(&real_##name##_p, __ATOMIC_ACQUIRE); \
  if (!real_##name) {                                                                  \
    real_##name = (__typeof__(&name))dlsym(RTLD_NEXT, #name);                          \
    __atomic_store_n(&real_##name##_p, real_##name, __ATOMIC_RELEASE);                 \
  }

void g_mutex_lock(GMutex* mutex) {
  REAL(g_mutex_lock);
  real_g_mutex_lock(mutex);
  __tsan_acquire(mutex);
}

gboolean g_mutex_trylock(GMutex* mutex) {
  REAL(g_mutex_trylock);
  gboolean locked = real_g_mutex_trylock(mutex);
  if (locked) __tsan_acquire(mutex);
  return locked;
}

void g_mutex_unlock(GMutex* mutex) {
  REAL(g_mutex_unlock);
  __tsan_release(mutex);
  real_g_mutex_unlock(mutex);
}

void g_rec_mutex_lock(GRecMutex* mutex) {
  REAL(g_rec_mutex_lock);
  real_g_rec_mutex_lock(mutex);
  __tsan_acquire(mutex);
}

gboolean g_rec_mutex_trylock(GRecMutex* mutex) {
  REAL(g_rec_mutex_trylock);
  gboolean locked = real_g_rec_mutex_trylock(mutex);
  if (locked) __tsan_acquire(mutex);
  return locked;
}

void g_rec_mutex_unlock(GRecMutex* mutex) {
  REAL(g_rec_mutex_unlock);
  __tsan_release(mutex);
  real_g_rec_mutex_unlock(mutex);
}

void g_cond_wait(GCond* cond, GMutex* mutex) {
  REAL(g_cond_wait);
  __tsan_release(mutex);
  real_g_cond_wait(cond, mutex);
  __tsan_acquire(mutex);
}

gboolean g_cond_wait_until(GCond* cond, GMutex* mutex, gint64 end_time) {
  REAL(g_cond_wait_until);
  __tsan_release(mutex);
  gboolean signalled = real_g_cond_wait_until(cond, mutex, end_time);
  __tsan_acquire(mutex);
  return signalled;
}
