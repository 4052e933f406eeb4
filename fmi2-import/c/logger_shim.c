/* The importer's logger (fmi2-import). fmi2CallbackLogger is
 * variadic, which stable Rust cannot define, so this shim formats the message
 * exactly as a printf-style importer does (vsnprintf of the message as the
 * format) and hands the result to Rust. A '%' that the FMU did not escape
 * shows up here as a mangled message. */
#include <stdarg.h>
#include <stdio.h>

extern void fmi2_import_record(void *environment, const char *instance_name, unsigned int status,
                               const char *category, const char *message);

void fmi2_import_logger(void *environment, const char *instance_name, unsigned int status,
                        const char *category, const char *message, ...) {
    char buffer[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(buffer, sizeof buffer, message ? message : "(NULL message)", args);
    va_end(args);
    fmi2_import_record(environment, instance_name, status, category, buffer);
}
