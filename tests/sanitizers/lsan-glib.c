/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* For the AddressSanitizer build only: GLib's quark tables, which GLib leaks on purpose.
 *
 * GLib keeps the strings of its quarks in one array of 2048 pointers (16 KB), allocated
 * by g_quark_init() when libglib loads. When a process makes its 2049th quark,
 * quark_new() (glib/gquark.c) allocates a table 2048 entries longer, copies the old
 * one into it and drops the old one without freeing it, so that g_quark_to_string() can read
 * the table without a lock (its comment: "This leaks the old quarks array"); again at
 * 4097, and so on. Any GStreamer program that loads many plugins gets there: `lftag
 * annotate` makes about 2,300 quarks on a short WebM file, a test program that scans
 * gst-plugins-good into a new registry in-process (GST_REGISTRY_FORK=no) about 3,500.
 * LeakSanitizer then reports a direct leak of 16384 bytes (and 32768 past 4096 quarks).
 * Proven with Debian 12's GLib 2.74.6: with fast_unwind_on_malloc=0 the report's frames
 * are libglib-2.0.so.0+0x647fb (the g_malloc (0x4000) after g_hash_table_new
 * (g_str_hash, g_str_equal), i.e. g_quark_init) called from libglib's constructor at
 * load (_dl_init); a program of GLib alone that makes 2,100 quarks with
 * g_quark_from_string() gets the same report, and one that makes 1,000 none.
 *
 * A suppression cannot name it: Debian's libglib has no symbols for g_quark_init and
 * quark_new and no frame pointers, so LeakSanitizer's stack of the leak is malloc <-
 * g_malloc and nothing more, and a line naming g_malloc or libglib would hide every
 * leak of memory GLib allocates, ours included (g_strdup, g_new). So,
 * linked into our programs that run GStreamer, this marks exactly the quark tables as
 * not leaked: each time a block the size of a quark table is allocated (GLib's own
 * g_new, just before it drops the old table), it finds the table in use through the
 * pointer libglib keeps in its writable data, recognised by its size and its contents
 * (its entry 1 is g_quark_to_string (1)), and tells LeakSanitizer to ignore that one
 * block. Every other allocation is checked as before; were GLib's tables to change
 * shape, nothing would match and the leak would be reported again. */
#define _GNU_SOURCE
#include <glib.h>
#include <link.h>
#include <sanitizer/allocator_interface.h>
#include <sanitizer/lsan_interface.h>
#include <stdint.h>
#include <string.h>

/* GLib's QUARK_BLOCK_SIZE: a quark table holds a multiple of this many pointers. */
#define QUARK_BLOCK_SIZE 2048

/* libglib's writable data (.data, .bss), where its pointer to the quark table is. */
static const uintptr_t* glib_data;
static size_t glib_data_words;

static int find_glib(struct dl_phdr_info* info, size_t size, void* data) {
  (void)size;
  (void)data;
  if (!info->dlpi_name || !strstr(info->dlpi_name, "/libglib-2.0.so")) return 0;
  for (int i = 0; i < info->dlpi_phnum; i++) {
    const ElfW(Phdr)* segment = &info->dlpi_phdr[i];
    if (segment->p_type == PT_LOAD && (segment->p_flags & PF_W)) {
      glib_data = (const uintptr_t*)(info->dlpi_addr + segment->p_vaddr);
      glib_data_words = segment->p_memsz / sizeof(uintptr_t);
      return 1;
    }
  }
  return 0;
}

static void on_malloc(const volatile void* block, size_t size) {
  (void)block;
  if (size == 0 || size % (QUARK_BLOCK_SIZE * sizeof(gchar*)) != 0) return;
  /* No allocation and no lock from here on: this runs inside malloc. */
  const gchar* first = g_quark_to_string(1);
  if (!first) return;
  for (size_t i = 0; i < glib_data_words; i++) {
    const void* table = (const void*)glib_data[i];
    if (!__sanitizer_get_ownership(table)) continue;
    const size_t bytes = __sanitizer_get_allocated_size(table);
    if (bytes == 0 || bytes % (QUARK_BLOCK_SIZE * sizeof(gchar*)) != 0) continue;
    if (((const gchar* const*)table)[1] == first) __lsan_ignore_object(table);
  }
}

/* The sanitizer installs a malloc hook only with a free hook. */
static void on_free(const volatile void* block) { (void)block; }

__attribute__((constructor)) static void install(void) {
  dl_iterate_phdr(find_glib, NULL);
  if (glib_data) __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}
