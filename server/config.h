/* config.h — command-line flags and the JSON configuration file.
 *
 * Precedence: built-in defaults < config file (--config) < flags. Unknown flags, unknown
 * config keys and bad values are errors with a message naming the offender. */
#ifndef FX_CONFIG_H
#define FX_CONFIG_H

#include "server.h"

enum config_result { CONFIG_OK, CONFIG_HELP, CONFIG_ERROR };

/* Fills cfg. On CONFIG_ERROR, err->message says what is wrong. */
enum config_result config_parse(int argc, char **argv, struct config *cfg, struct fx_err *err);
void config_usage(FILE *out);
void config_free(struct config *cfg);

#endif
